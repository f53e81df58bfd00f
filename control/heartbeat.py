"""Client liveness: the controller holds when its client falls silent, and exits when orphaned."""

from __future__ import annotations

import time


class ClientWatch:
    """Inputs: every message from the client (``heard``) and the wall clock. Outputs: ``lost``
    once the client is silent past ``timeout_ns``, ``orphaned`` past ``orphan_ns`` more."""

    def __init__(self, timeout_ns: int, orphan_ns: int) -> None:
        self.timeout_ns = timeout_ns
        self.orphan_ns = orphan_ns
        self.last_heard_ns = time.monotonic_ns()
        self.lost_since = 0

    def heard(self) -> bool:
        """A message arrived; True if the client had been given up for lost."""
        self.last_heard_ns = time.monotonic_ns()
        was_lost = bool(self.lost_since)
        self.lost_since = 0
        return was_lost

    def gone(self) -> None:
        """The channel closed: the client will never be heard again."""
        self.last_heard_ns = 0

    def check(self) -> tuple[bool, bool]:
        """(just lost, orphaned): the client fell silent this tick; it has been lost too long."""
        wall = time.monotonic_ns()
        if not self.lost_since:
            if wall - self.last_heard_ns > self.timeout_ns:
                self.lost_since = wall
                return True, False
            return False, False
        return False, wall - self.lost_since > self.orphan_ns
