"""Publishing the status (``visual``'s feed, section 5.1): one record a tick under the seqlock.

Inputs: the components' state at the end of a tick. Output: the status record of
``StatusLayout`` in the control segment, which every client reads without ever
seeing a torn record.
"""

from __future__ import annotations

import math
import time

from control.rt.encoder_input import EncoderInput
from control.rt.guards import Guards
from control.rt.latency import LatencyStats
from control.rt.layout import ControlLayout, Flag
from control.rt.modes import ModeMachine
from control.rt.seqlock import SeqlockWriter
from hw.backend import Backend

(ESTOP_LATCHED, ESTOP_INPUT, HOMED, UI_LOST, LINK_FAULT, REALTIME, MOVING, FAULT, PAUSED,
 SETTLING, REDUCED) = (int(f) for f in Flag)  # in Flag's order; plain ints, as enum ORs cost µs


class Publisher:
    def __init__(self, buf: memoryview, layout: ControlLayout, started_ns: int) -> None:
        self.writer = SeqlockWriter(buf, layout.status_offset, layout.status.struct)
        self.encode = layout.status.encode
        self.started_ns = started_ns
        self.no_settle = [math.nan] * layout.n  # settle_s while no move settles

    def publish(self, tick: int, now: int, modes: ModeMachine, guards: Guards,
                encoders: EncoderInput, backend: Backend, latency: LatencyStats,
                valve: list[float], client_lost: bool, realtime: bool) -> None:
        move = modes.move
        settle = move.settle if move is not None else None
        flags = ((ESTOP_LATCHED if guards.latched else 0)
                 | (ESTOP_INPUT if backend.estop else 0)
                 | (HOMED if encoders.homed else 0)
                 | (UI_LOST if client_lost else 0)
                 | (LINK_FAULT if backend.fault else 0)
                 | (REALTIME if realtime else 0)
                 | (MOVING if move is not None else 0)
                 | (FAULT if guards.reason else 0)
                 | (PAUSED if move is not None and modes.feed.paused else 0)
                 | (SETTLING if settle is not None else 0)
                 | (REDUCED if modes.speed.reduced else 0))
        feed = modes.feed
        self.writer.write(*self.encode(
            tick, now - self.started_ns, time.monotonic_ns(), modes.mode, flags,
            move.move_id if move else 0, min(move.index, move.layout.samples) if move else 0,
            move.layout.samples if move else 0, latency, (feed.override, feed.rate),
            backend.supply_mpa, modes.position, modes.desired, modes.duty, valve,
            settle.settled_s if settle is not None else self.no_settle, encoders.raw,
            encoders.glitches, backend.counters, guards.reason))

    def release(self) -> None:
        self.writer.release()
