"""The one place a finished move's segment becomes a saved run (``keep``), and the worker
thread that does it for a client (``RunKeeper``), so that the thread that hears the
controller (its events, E-stops and faults, its death) never waits on a disk.

Four parties save runs (``control/runs.py`` says why): the client when its move ends
(``ControlClient._finish`` hands the move to its keeper and returns at once), the
controller service for a client that has gone (``service.save_departed``, on its embedded
client's keeper), the controller after its loop (``control/rt/saver.py``) and the next client
to start (``control/recovery.py``); the last two call ``keep`` on their own thread, where
nothing waits on them. All keep one rule: a move's segment is unlinked only once its run
is saved (or holds no sample, for a client that saves none of those), so a run that cannot
be saved stays whole there for the next start to recover (``RunKept.kept``). A keeper saves
its runs one after the other, in the order they were handed over.
"""

from __future__ import annotations

import logging
import queue
import threading
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from multiprocessing.shared_memory import SharedMemory
from pathlib import Path
from typing import Any

from control.recorder import (
    RecorderError,
    Run,
    RunFiles,
    find_run,
    remove_incomplete,
    remove_stale_temps,
    save_run,
)
from control.rt import shm
from control.rt.layout import MoveLayout
from control.runs import decode_meta, run_from_segment

log = logging.getLogger("servodesk.runs")

Timeline = Mapping[str, Sequence[tuple[float, float]]]
# a run's metrics and what goes into its metadata with them (a client's; control.motion.plan)
Measure = Callable[[Run], tuple[Any, Mapping[str, Any]]]


@dataclass(frozen=True)
class FinishedMove:
    """A move that has ended: its segment and layout, the metadata its client wrote there,
    how it ended and its ``timeline`` (``ActiveMove.timeline``); ``saved`` is the JSON of
    its run if the controller saved it already (its client was gone)."""

    segment: SharedMemory
    layout: MoveLayout
    meta: Mapping[str, Any]
    status: str
    timeline: Timeline | None = None
    saved: str = ""

    @classmethod
    def in_segment(cls, segment: SharedMemory, status: str | None = None,
                   timeline: Timeline | None = None) -> FinishedMove:
        """The move ``segment`` holds, its layout and metadata read from it; with no
        ``status`` or ``timeline``, those the controller wrote there when the move ended ("" and
        None if it never did). ValueError if it is no move segment this servodesk can read."""
        layout = MoveLayout.read_header(segment.buf)
        meta = decode_meta(layout.read_meta(segment.buf))
        ended = layout.read_status(segment.buf) if status is None else status
        if timeline is None:  # a controller whose client had gone wrote it there
            timeline = layout.read_timeline(segment.buf)
        return cls(segment, layout, meta, ended, timeline)

    @property
    def data_dir(self) -> Path:
        """Where its client saves runs (the segment says, ``control/runs.py``)."""
        return Path(str(self.meta["data_dir"]))


@dataclass(frozen=True)
class RunKept:
    """What became of a finished move's run: the run (None if its segment could not be
    read), where it is saved (None: nowhere, ``problem`` says why), and its metrics."""

    run: Run | None
    files: RunFiles | None
    problem: str = ""
    results: Any = ()

    @property
    def kept(self) -> bool:
        """Not saved, so whole in its segment for the next start (``control/recovery.py``)."""
        return self.files is None and (self.run is None or bool(self.run.samples))


def keep(move: FinishedMove, *, measure: Measure | None = None, fallback: Path | None = None,
         recovering: bool = False, save_empty: bool = True,
         release: Callable[[bool], None] | None = None) -> RunKept:
    """Copy ``move``'s run out of its segment, ``measure`` it, save it where its client
    saves runs (else in ``fallback``), and let go of the segment (``release``, by default
    ``shm.release``): unlinked if the run is saved, or it holds no sample and
    ``save_empty`` is false (then it is not saved). ``recovering``: a run a killed process
    left; one already saved is not saved again, and what a killed save left is cleared."""
    let_go = release or (lambda unlink: shm.release(move.segment, unlink=unlink))
    unlink = False
    try:
        run = run_from_segment(move.segment.buf, move.layout, dict(move.meta), move.status,
                               move.timeline)
        results, extra = measure(run) if measure is not None else ((), {})
        if move.saved:  # by the controller, its client gone: without the metrics
            files, problem = RunFiles.from_json(Path(move.saved)), ""
        elif run.samples or save_empty:
            run = replace(run, meta={**run.meta, **extra}) if extra else run
            files, problem = _save(run, move.data_dir, fallback, recovering)
        else:
            files, problem = None, ""
        kept = RunKept(run, files, problem, results)
        unlink = not kept.kept
        return kept
    except (OSError, KeyError, TypeError, ValueError) as exc:  # metadata that is not a run's
        return RunKept(None, None, f"{type(exc).__name__}: {exc}")
    finally:
        let_go(unlink)


def _save(run: Run, data_dir: Path, fallback: Path | None, recovering: bool
          ) -> tuple[RunFiles | None, str]:
    """Save ``run`` in ``data_dir``, else in ``fallback``; the files, or why neither."""
    if recovering:
        found = find_run(data_dir, run) or (find_run(fallback, run) if fallback else None)
        if found is not None:
            return found, ""
        remove_incomplete(data_dir, run)
        remove_stale_temps(data_dir, shm.pid_alive)
    try:
        return save_run(run, data_dir), ""
    except RecorderError as exc:
        if fallback is None:
            return None, str(exc)
        try:
            return save_run(run, fallback), ""
        except RecorderError as again:
            return None, str(again)


class RunKeeper:
    """A worker thread that keeps finished moves' runs (``keep``), one after the other, and
    says what became of each (``hand``'s ``done``, called on that thread)."""

    def __init__(self, name: str = "servodesk-runs") -> None:
        self.name = name
        self._jobs: queue.Queue[tuple[FinishedMove, Callable[[RunKept], None], dict]] = \
            queue.Queue()
        self._lock = threading.Condition()
        self._in_hand = 0
        # started now: a thread started where a move ends would make that thread wait for it
        threading.Thread(target=self._work, name=name, daemon=True).start()

    def hand(self, move: FinishedMove, done: Callable[[RunKept], None], **how: Any) -> None:
        """Keep ``move``'s run on the worker thread (``how``: ``keep``'s options), then call
        ``done`` with what became of it; returns at once."""
        with self._lock:
            self._in_hand += 1
        self._jobs.put((move, done, how))

    @property
    def in_hand(self) -> int:
        """Runs handed over and not yet kept."""
        return self._in_hand

    def wait(self, timeout_s: float) -> bool:
        """Wait until every run handed over is kept, at most ``timeout_s``; whether it is."""
        with self._lock:
            return self._lock.wait_for(lambda: self._in_hand == 0, timeout_s)

    def _work(self) -> None:
        while True:
            move, done, how = self._jobs.get()
            try:
                try:
                    kept = keep(move, **how)
                except Exception as exc:  # never leave a handle waiting: its segment stays
                    log.exception("keeping a run failed")
                    kept = RunKept(None, None, f"{type(exc).__name__}: {exc}")
                done(kept)
            except Exception:
                log.exception("after keeping a run")
            finally:
                with self._lock:
                    self._in_hand -= 1
                    self._lock.notify_all()
