"""The client's words: its heartbeat and its E-stop, read from shared memory every tick.

The client writes both into the control segment (``ControlLayout.client_words``)
rather than the command channel, so a full or frozen channel can delay neither:
the controller holds when the heartbeat stops changing for ``timeout_ns``, exits
when orphaned ``orphan_ns`` later, and latches the E-stop the tick after the
E-stop count changes.
"""

from __future__ import annotations

import time

from control.layout import ESTOP_WORD, HEARTBEAT_WORD


class ClientWatch:
    """Inputs: the client's words (a ``q`` view), every message from the client (``heard``)
    and the wall clock. Outputs: ``lost`` once the client is silent past ``timeout_ns``,
    ``orphaned`` past ``orphan_ns`` more, ``estop_pressed`` when its E-stop count moved."""

    def __init__(self, words: memoryview, timeout_ns: int, orphan_ns: int) -> None:
        self.words = words
        self.timeout_ns = timeout_ns
        self.orphan_ns = orphan_ns
        self.last_heard_ns = time.monotonic_ns()
        self.last_beat = words[HEARTBEAT_WORD]
        self.estops_seen = words[ESTOP_WORD]
        self.lost_since = 0
        self.closed = False

    def heard(self) -> None:
        """The client spoke (a message or a new heartbeat)."""
        self.last_heard_ns = time.monotonic_ns()

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
        beat = self.words[HEARTBEAT_WORD]
        if beat != self.last_beat and not self.closed:
            self.last_beat = beat
            self.heard()
        wall = time.monotonic_ns()
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
