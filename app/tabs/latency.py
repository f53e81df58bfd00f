"""Latency: the loop's wake-up lateness as Table 2.1 of the thesis, from the running loop.

The controller histograms every tick's lateness in 5 µs bins from its start.
"Run a fresh test" takes the difference of two snapshots ``TEST_S`` apart, so
it measures now (under whatever load the machine has now) without restarting
anything.

The histogram's last bin holds every tick at least 2 ms late, so a test's
maximum is known only to its bin; when ticks fell in the last bin it is at
least 2,000 µs, and exact only if the run's maximum (``status.late_max_us``,
kept to the nanosecond) rose during the test. Each maximum says which it is.

The tab also watches the loop while hidden (``StallWatch``): a wake-up later
than the machine's ``stall_ms`` (50 ms by default) goes into the event log.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import ClassVar, Literal

import numpy as np
from rich.bar import Bar
from rich.table import Table
from rich.text import Text
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal
from textual.message import Message
from textual.widgets import Button, Static

from app.desk import Desk
from app.tabs.tab import TabPage
from control.link import ControllerError
from control.rt.layout import HIST_BIN_NS, HIST_BINS, LatencyHistogram

TEST_S = 10.0
FINE_ROWS = 20  # 5 µs rows: 0-100 µs at most
BULK_FRACTION = 0.995  # the fine rows cover this share of the ticks
TAIL_EDGES_US = (50.0, 100.0, 200.0, 500.0, 1000.0)  # wider rows for the tail
STALL_CHECK_S = 0.5  # the stall watch reads the histogram this often, shown or not
OVER_US = HIST_BINS * HIST_BIN_NS / 1e3  # the last bin: every tick this late or later
THESIS = "thesis, Table 2.1 (486-66, RTLinux): min 11.5 µs · average 13.97 µs · max 54 µs · " \
         "100,290 interrupts"


@dataclass(frozen=True)
class Lateness:
    """Counts per 5 µs bin and their summary, over the whole run or over one test.

    ``max_known`` says what ``max_us`` is: ``exact`` (measured), ``bin`` (the upper edge
    of the highest bin with a tick: the maximum is below it), or ``over`` (ticks fell in
    the last bin, ≥ 2 ms, and the run's maximum did not rise: the maximum is at least
    ``max_us`` = 2,000 µs and at most ``run_max_us``, the run's, which came before)."""

    counts: np.ndarray
    ticks: int
    mean_us: float
    min_us: float
    max_us: float
    overruns: int
    exact_extremes: bool  # min measured, or only known to the bin
    max_known: Literal["exact", "bin", "over"] = "exact"
    run_max_us: float = 0.0

    @classmethod
    def total(cls, h: LatencyHistogram) -> Lateness:
        return cls(h.counts.copy(), h.ticks, h.mean_us, h.min_us, h.max_us, h.overruns, True,
                   "exact", h.max_us)

    def since(self, before: Lateness) -> Lateness:
        counts = self.counts - before.counts
        ticks = self.ticks - before.ticks
        total_us = self.mean_us * self.ticks - before.mean_us * before.ticks
        nonzero = np.flatnonzero(counts)
        bin_us = HIST_BIN_NS / 1e3
        low = float(nonzero[0] * bin_us) if len(nonzero) else 0.0
        high = float((nonzero[-1] + 1) * bin_us) if len(nonzero) else 0.0
        known: Literal["exact", "bin", "over"] = "bin"
        if self.max_us > before.max_us:  # the run's maximum rose: it is this window's
            high, known = self.max_us, "exact"
        elif counts[-1]:
            high, known = OVER_US, "over"
        return Lateness(counts, ticks, total_us / ticks if ticks else 0.0, low, high,
                        self.overruns - before.overruns, False, known, self.max_us)

    def max_text(self) -> str:
        """The maximum, saying how well it is known."""
        if self.max_known == "exact":
            return f"{self.max_us:.1f} µs"
        if self.max_known == "bin":
            return f"≤ {self.max_us:.0f} µs"
        return (f"≥ {OVER_US:.0f} µs (the last bin holds every tick ≥ 2 ms; the run's longest, "
                f"{self.run_max_us:,.0f} µs, came earlier)")


@dataclass
class StallWatch:
    """Wake-ups later than ``threshold_us`` from successive histograms: a rise of the run's
    maximum past it is one such stall, measured; so is a rise of the longest tick's compute
    past it (``compute_max_us``: the loop stopped or starved mid-tick, its next deadlines
    skipped as overruns, so no wake-up was late); more than ``threshold_us`` of missed
    ticks between two looks is at least one stall shorter than the maximum so far, or one
    in the part of a tick neither figure times (its publishing: no wake-up late, no long
    compute), known only that well. ``late_us``: the last stall's length, as well as known
    (a burst's: its missed ticks' time)."""

    threshold_us: float
    period_us: float
    max_us: float = 0.0
    compute_max_us: float = 0.0
    overruns: int = 0
    over: int = 0
    late_us: float = 0.0

    def sample(self, h: LatencyHistogram, compute_max_us: float = 0.0) -> str:
        """What the loop did since the last sample, if it stalled; else ""."""
        missed, over = h.overruns - self.overruns, int(h.counts[-1]) - self.over
        rose = h.max_us > max(self.max_us, self.threshold_us)
        held = compute_max_us > max(self.compute_max_us, self.threshold_us)
        self.max_us, self.overruns, self.over = max(self.max_us, h.max_us), h.overruns, int(
            h.counts[-1])
        self.compute_max_us = max(self.compute_max_us, compute_max_us)
        if rose:
            self.late_us = h.max_us
            return (f"controller loop stalled: a tick woke {h.max_us / 1e3:,.1f} ms late, the "
                    "longest since it started")
        if held:
            self.late_us = compute_max_us
            return (f"controller loop stalled: a tick ended {compute_max_us / 1e3:,.1f} ms late "
                    f"(held up mid-tick, {missed} ticks skipped), the longest since it started")
        if missed * self.period_us > self.threshold_us:
            self.late_us = missed * self.period_us
            return (f"controller loop stalled: {missed} ticks missed since the last look, "
                    f"{over} woke ≥ 2 ms late (none later than the longest so far, "
                    f"{self.max_us / 1e3:,.1f} ms)")
        return ""


def histogram_rows(counts: np.ndarray, fine_rows: int = FINE_ROWS
                   ) -> list[tuple[float, float, int]]:
    """``(from µs, to µs, ticks)``: 5 µs rows where most ticks are (as Table 2.1), then a
    few wider rows for the tail, then the overflow bin; empty tail rows are left out."""
    bin_us = HIST_BIN_NS / 1e3
    total = int(counts.sum())
    if total == 0:
        return []
    overflow = len(counts) - 1  # the last bin holds everything beyond the histogram
    cumulative = np.cumsum(counts)
    bulk = int(np.searchsorted(cumulative, BULK_FRACTION * total)) + 1
    fine = max(4, min(fine_rows, bulk))
    rows = [(i * bin_us, (i + 1) * bin_us, int(counts[i])) for i in range(fine)]
    edge = fine
    for stop_us in (*TAIL_EDGES_US, overflow * bin_us):
        stop = min(overflow, int(stop_us / bin_us))
        if stop <= edge:
            continue
        n = int(counts[edge:stop].sum())
        if n:
            rows.append((edge * bin_us, stop * bin_us, n))
        edge = stop
    if counts[overflow]:
        rows.append((overflow * bin_us, math.inf, int(counts[overflow])))
    return rows


class LatencyTab(TabPage):
    """The Table 2.1 histogram, live, and a fresh test on demand; stalls go into the log."""

    REFRESH_HZ = 2.0
    TITLE = "Latency"
    LATER = ("#latency-tables",)
    BINDINGS: ClassVar = [Binding("t", "fresh_test", f"fresh {TEST_S:g} s test")]

    @dataclass
    class Stalled(Message):
        """The loop woke, or ended a tick, later than the machine's ``stall_ms`` (``what``
        says how late)."""

        what: str
        late_max_us: float

    def __init__(self, desk: Desk, *, id: str | None = None) -> None:
        super().__init__(desk, id=id)
        self.test_start: Lateness | None = None
        self.test_started_at = 0.0
        self.fresh: Lateness | None = None
        self.stalls = StallWatch(self.machine.supervision.stall_s * 1e6,
                                 self.machine.sample_time_s * 1e6)

    def on_mount(self) -> None:
        self.set_interval(STALL_CHECK_S, self.watch_stalls)  # shown or not

    def watch_stalls(self) -> None:
        client = self.client
        if client is None:
            return
        try:
            histogram, status = client.histogram(), client.status()
        except (ControllerError, ValueError, TimeoutError):  # closed or died while we asked
            return
        what = self.stalls.sample(histogram, status.compute_max_us)
        if what:
            self.post_message(self.Stalled(what, self.stalls.late_us))

    def compose(self) -> ComposeResult:
        with Horizontal(id="latency-controls"):
            yield Button(f"Run a fresh test ({TEST_S:g} s)", id="latency-test",
                         variant="primary")
            yield Static(id="latency-test-state")
        with Horizontal(id="latency-tables"):
            yield Static(id="latency-total")
            yield Static(id="latency-fresh")
        yield Static(Text(THESIS, "dim"), id="latency-thesis")

    def focus_main(self) -> None:
        self.query_one("#latency-test", Button).focus()

    def on_button_pressed(self, event: Button.Pressed) -> None:
        if event.button.id == "latency-test":
            event.stop()
            self.action_fresh_test()

    def action_fresh_test(self) -> None:
        client = self.client
        if client is None:
            self.notify("latency test: the controller is not running", severity="error")
            return
        if self.test_start is not None:
            return
        self.test_start = Lateness.total(client.histogram())
        self.test_started_at = time.monotonic()
        self.query_one("#latency-test", Button).disabled = True
        self.set_timer(TEST_S, self._finish_test)
        self.refresh_live()

    def _finish_test(self) -> None:
        client, start = self.client, self.test_start
        self.test_start = None
        self.query_one("#latency-test", Button).disabled = False
        if client is None or start is None:
            return
        self.fresh = Lateness.total(client.histogram()).since(start)
        self.notify(f"latency test done: {self.fresh.ticks} ticks, average "
                    f"{self.fresh.mean_us:.1f} µs, max {self.fresh.max_text()}, "
                    f"{self.fresh.overruns} overruns")
        self.refresh_live()

    def refresh_live(self) -> None:
        client = self.client
        if client is None:
            return
        total = Lateness.total(client.histogram())
        self.query_one("#latency-total", Static).update(
            _table(total, "since the controller started"))
        if self.fresh is not None:
            self.query_one("#latency-fresh", Static).update(
                _table(self.fresh, f"fresh {TEST_S:g} s test"))
        state = self.query_one("#latency-test-state", Static)
        if self.test_start is not None:
            left = TEST_S - (time.monotonic() - self.test_started_at)
            state.update(Text(f"  testing… {max(0.0, left):.0f} s left", "yellow"))
        else:
            state.update(Text("  lateness = wake-up time − deadline, 5 µs bins", "dim"))


def _table(h: Lateness, title: str) -> Table:
    approx = "" if h.exact_extremes else "≈"
    table = Table(title=f"{title}: {h.ticks:,} ticks", title_justify="left", title_style="bold",
                  box=None, padding=(0, 1), caption_justify="left", header_style="bold",
                  expand=True,
                  caption=f"min {approx}{h.min_us:.1f} µs · average {h.mean_us:.2f} µs · max "
                          f"{h.max_text()} · overruns {h.overruns}")
    table.add_column("lateness µs", justify="right", no_wrap=True)
    table.add_column("ticks", justify="right")
    table.add_column("%", justify="right")
    table.add_column("", no_wrap=True, ratio=1)  # the bars take the width there is
    rows = histogram_rows(h.counts)
    peak = max((n for *_, n in rows), default=0)
    for lo, hi, n in rows:
        span = f"{lo:g}–{hi:g}" if math.isfinite(hi) else f"≥ {lo:g}"
        share = 100.0 * n / h.ticks if h.ticks else 0.0
        table.add_row(span, f"{n:,}", f"{share:.2f}", Bar(peak or 1, 0, n, color="cyan"))
    return table
