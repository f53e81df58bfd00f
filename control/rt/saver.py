"""The runs the controller finished with its client gone: kept, then handed over — never
saved in the control process.

While its client is silent the controller keeps each finished move's segment
(``keep``: no file I/O, nothing unlinked). If the client comes back it is told
of the move and saves it itself (``drop``). Once the loop has ended — valves
closed, nothing real-time left to do — ``hand_over`` writes into each kept segment
how the move ended and its timeline (stalls, feed changes, holds, supply), and the
control process starts a saver (``python -m control.recovery --after PID SEGMENT…``) that saves
them with the run keeper once the controller has exited. A controller killed before
that leaves the segments in /dev/shm, where the next client start finds them.
"""

from __future__ import annotations

from control.rt import shm
from control.rt.modes import ActiveMove


class RunSaver:
    """Keeps an orphaned move's segment; after the loop, hands its run over to a saver."""

    def __init__(self) -> None:
        self.kept: list[ActiveMove] = []

    def keep(self, move: ActiveMove) -> None:
        self.kept.append(move)

    def drop(self) -> None:
        """The client is back and will save what it is told of: let go of the segments."""
        for move in self.kept:
            release(move, unlink=False)
        self.kept.clear()

    def hand_over(self) -> list[str]:
        """After the loop: write each kept move's timeline into its segment (its status is
        there already) and let go of it, not unlinked; the segments' names."""
        names = []
        for move in self.kept:
            move.layout.write_timeline(move.segment.buf, move.timeline())
            names.append(move.segment.name)
            release(move, unlink=False)
        self.kept.clear()
        return names


def release(move: ActiveMove, unlink: bool) -> None:
    """Drop every view of the move's path and segment, then close (and maybe unlink) it."""
    move.path.release()
    move.path_map.close()
    move.recorded.release()
    shm.release(move.segment, unlink=unlink)
