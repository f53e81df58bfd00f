"""Saving the runs the controller finished on its own, its client gone — never in the tick.

While its client is silent the controller keeps each finished move's segment
(``keep``: no file I/O, nothing unlinked). If the client comes back it is told
of the move and saves it itself (``drop``). Once the loop has ended — valves
closed, nothing real-time left to do — ``save_kept`` writes what is still kept.
A controller killed before that leaves the segments in /dev/shm, where the next
client start finds them.
"""

from __future__ import annotations

from dataclasses import dataclass

from control import shm
from control.modes import ActiveMove
from control.run_keeper import FinishedMove, keep


@dataclass
class KeptRun:
    move: ActiveMove
    status: str


class RunSaver:
    """Keeps an orphaned move's segment; after the loop, saves its run where its client saved
    runs (the segment says where, ``control/runs.py``)."""

    def __init__(self) -> None:
        self.kept: list[KeptRun] = []

    def keep(self, move: ActiveMove, status: str) -> None:
        self.kept.append(KeptRun(move, status))

    def drop(self) -> None:
        """The client is back and will save what it is told of: let go of the segments."""
        for kept in self.kept:
            release(kept.move, unlink=False)
        self.kept.clear()

    def save_kept(self) -> list[str]:
        """After the loop: save every kept run and unlink its segment; the JSON paths."""
        saved = [path for kept in self.kept if (path := self.save(kept.move, kept.status))]
        self.kept.clear()
        return saved

    def save(self, move: ActiveMove, status: str) -> str:
        """Save ``move`` as recorded (``control/run_keeper.py``, here on the loop's thread, its
        work done) and let go of it; its JSON path, or "" if it could not be saved (then its
        segment stays for the next client to start: ``control/recovery.py``)."""
        try:
            finished = FinishedMove.in_segment(move.segment, status, move.timeline())
        except (UnicodeDecodeError, ValueError):
            release(move, unlink=False)
            return ""
        kept = keep(finished, release=lambda unlink: release(move, unlink))
        return str(kept.files.json) if kept.files is not None else ""


def release(move: ActiveMove, unlink: bool) -> None:
    """Drop every view of the move's path and segment, then close (and maybe unlink) it."""
    move.path.release()
    move.path_map.close()
    move.recorded.release()
    shm.release(move.segment, unlink=unlink)
