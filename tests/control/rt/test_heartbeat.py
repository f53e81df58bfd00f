"""ClientWatch: the client's silence is counted over time the controller was awake to hear
it. Driven by a clock the test sets, over real shared words (the ``q`` view the loop reads)."""

from __future__ import annotations

import pytest

from control.rt.heartbeat import STALL_NS, STALLS_FORGIVEN, ClientWatch
from control.rt.layout import HEARTBEAT_WORD

MS = 1_000_000
TIMEOUT = 250 * MS
ORPHAN = 5_000 * MS


class Clock:
    def __init__(self) -> None:
        self.ns = 1_000 * MS

    def __call__(self) -> int:
        return self.ns


@pytest.fixture
def watch() -> tuple[ClientWatch, Clock, memoryview]:
    clock = Clock()
    words = memoryview(bytearray(16)).cast("q")
    return ClientWatch(words, TIMEOUT, ORPHAN, clock), clock, words


def run(watch: ClientWatch, clock: Clock, ms: int, beat_every_ms: int | None = None,
        words: memoryview | None = None) -> list[tuple[bool, bool, bool]]:
    """Check every millisecond for ``ms``, the client beating every ``beat_every_ms``."""
    seen = []
    for k in range(ms):
        clock.ns += MS
        if beat_every_ms and words is not None and k % beat_every_ms == 0:
            words[HEARTBEAT_WORD] = clock.ns
        seen.append(watch.check())
    return seen


def test_a_silent_client_is_lost_after_the_timeout_and_back_when_it_beats(watch) -> None:
    w, clock, words = watch
    run(w, clock, 100, 50, words)
    seen = run(w, clock, 400)
    # the last beat was 49 ms before this run: lost the first check more than 250 ms after it
    assert [k for k, (lost, _, _) in enumerate(seen) if lost] == [201]
    words[HEARTBEAT_WORD] = clock.ns + 1
    assert run(w, clock, 1) == [(False, True, False)], "a new heartbeat: back"


def test_a_stall_of_the_controller_is_not_the_clients_silence(watch) -> None:
    """The controller stopped for 400 ms (the machine stalled): the client, which had no CPU
    either, did not beat meanwhile; when the controller runs again it is not lost, and a
    client that beats within the timeout after that never is."""
    w, clock, words = watch
    run(w, clock, 100, 50, words)
    clock.ns += 400 * MS
    assert w.check() == (False, False, False)
    assert not any(lost for lost, _, _ in run(w, clock, 200))
    assert not any(lost for lost, _, _ in run(w, clock, 1_000, 50, words))


def test_a_client_frozen_through_a_stall_is_lost_the_timeout_after_it(watch) -> None:
    w, clock, words = watch
    run(w, clock, 100, 50, words)
    clock.ns += 2 * STALL_NS
    w.check()
    seen = run(w, clock, 300)
    lost_at = next(k for k, (lost, _, _) in enumerate(seen) if lost)
    assert 200 <= lost_at <= 250, lost_at  # the beat was 50 ms old when the stall began


def test_short_gaps_count_against_the_client(watch) -> None:
    """Gaps under STALL_NS are ordinary lateness: they count as the client's silence."""
    w, clock, words = watch
    run(w, clock, 1, 1, words)
    lost = False
    for _ in range(30):
        clock.ns += STALL_NS // 2
        lost = lost or w.check()[0]
    assert lost, "15 × 10 ms of silence is past the 250 ms timeout"


def test_a_closed_channel_is_lost_at_once_even_after_a_stall(watch) -> None:
    w, clock, words = watch
    run(w, clock, 10, 5, words)
    w.gone()
    clock.ns += 10 * STALL_NS
    assert w.check()[0]


def test_a_controller_that_stalls_tick_after_tick_still_finds_a_silent_client(watch) -> None:
    """Gaps of 25 ms at every check are an overloaded controller, not a stall: after
    STALLS_FORGIVEN of them the silence counts, and a client that never beats is lost."""
    w, clock, words = watch
    run(w, clock, 1, 1, words)
    lost_at = None
    for k in range(100):
        clock.ns += STALL_NS + 5 * MS
        if w.check()[0]:
            lost_at = k
            break
    assert lost_at is not None, "an overloaded controller never found the silent client"
    assert lost_at <= STALLS_FORGIVEN + TIMEOUT // (STALL_NS + 5 * MS) + 1, lost_at


def test_a_client_heard_again_is_forgiven_the_next_stall(watch) -> None:
    w, clock, words = watch
    for _ in range(3 * STALLS_FORGIVEN):
        run(w, clock, 10, 5, words)
        clock.ns += 400 * MS  # a stall, then the client beats again
        assert w.check() == (False, False, False)
