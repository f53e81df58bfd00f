"""The client's words: its heartbeat and its E-stop, read from shared memory every tick.

The client writes both into the control segment (``ControlLayout.client_words``)
rather than the command channel, so a full or frozen channel can delay neither:
the controller holds when the heartbeat stops changing for ``timeout_ns``, exits
when orphaned ``orphan_ns`` later, and latches the E-stop the tick after the
E-stop count changes.

The client's silence is counted only over time the controller was awake to hear it: a
gap of more than ``STALL_NS`` between two checks means the controller itself was stopped
(the machine stalled, or the hypervisor, or a SIGSTOP), and a client that had no CPU either
is not blamed for it. A client that is really gone is still found: its channel closes at
once (``gone``), and a frozen one is silent ``timeout_ns`` after the controller runs again.
Only ``STALLS_FORGIVEN`` stalls are forgiven within one silence: a controller that stalls
tick after tick is overloaded (its overrun watch holds), and a client silent through that
is lost as usual.
"""

from __future__ import annotations

import time
from collections.abc import Callable

from control.rt.layout import ESTOP_WORD, HEARTBEAT_WORD

STALL_NS = 20_000_000  # a gap between checks this long is the controller's own stall
STALLS_FORGIVEN = 3  # stalls not counted against the client within one silence


class ClientWatch:
    """Inputs: the client's words (a ``q`` view), every message from the client (``heard``)
    and the wall clock. Outputs: ``lost`` once the client is silent past ``timeout_ns``,
    ``orphaned`` past ``orphan_ns`` more, ``estop_pressed`` when its E-stop count moved."""

    def __init__(self, words: memoryview, timeout_ns: int, orphan_ns: int,
                 clock: Callable[[], int] = time.monotonic_ns) -> None:
        self.words = words
        self.timeout_ns = timeout_ns
        self.orphan_ns = orphan_ns
        self.clock = clock
        self.last_heard_ns = self.last_check_ns = clock()
        self.last_beat = words[HEARTBEAT_WORD]
        self.estops_seen = words[ESTOP_WORD]
        self.lost_since = 0
        self.closed = False
        self.forgiven = 0  # stalls not counted against the client since it was last heard

    def heard(self) -> None:
        """The client spoke (a message or a new heartbeat)."""
        self.last_heard_ns = self.clock()

    def gone(self) -> None:
        """The channel closed: the client will never be heard again."""
        self.closed = True
        self.last_heard_ns = 0

    def estop_pressed(self) -> bool:
        """True once for every change of the client's E-stop count."""
        count = self.words[ESTOP_WORD]
        if count == self.estops_seen:
            return False
        self.estops_seen = count
        return True

    def check(self) -> tuple[bool, bool, bool]:
        """(just lost, back, orphaned): the client fell silent this tick; it was lost and has
        been heard since; it has been lost too long."""
        wall = self.clock()
        stalled = wall - self.last_check_ns
        self.last_check_ns = wall
        if (stalled > STALL_NS and self.forgiven < STALLS_FORGIVEN
                and not (self.lost_since or self.closed)):
            self.last_heard_ns += stalled  # the controller's stall, not the client's silence
            self.forgiven += 1
        beat = self.words[HEARTBEAT_WORD]
        if beat != self.last_beat and not self.closed:
            self.last_beat = beat
            self.last_heard_ns = wall
            self.forgiven = 0
        if not self.lost_since:
            if wall - self.last_heard_ns > self.timeout_ns:
                self.lost_since = wall
                return True, False, False
            return False, False, False
        if self.last_heard_ns > self.lost_since:
            self.lost_since = 0
            return False, True, False
        return False, False, wall - self.lost_since > self.orphan_ns

    def release(self) -> None:
        self.words.release()
