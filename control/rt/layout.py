"""The shared-memory layout between the control subprocess and its client.

Two kinds of segment, both documented in ``docs/shared_memory.md``:

* the **control segment**, one per session: a header with the layout version,
  the status snapshot (seqlock, written every tick), the hold and track
  coefficient sets (seqlock, written by the client) and the latency histogram;
* a **move segment** per move, sized for that move: the desired path or duty
  profile in, the recorded run out, and a progress counter.

Everything is little-endian; the 8-byte counters sit on 8-byte boundaries.
"""

from __future__ import annotations

import json
import struct
from dataclasses import dataclass
from enum import IntEnum, IntFlag
from operator import attrgetter
from typing import TYPE_CHECKING

import numpy as np

from hw.backend import LinkCounters
from hw.machine import MAX_TAPS, Coefficients

if TYPE_CHECKING:
    from control.rt.latency import LatencyStats

LAYOUT_VERSION = 7
CONTROL_MAGIC = b"SDSK"
MOVE_MAGIC = b"SDMV"
HIST_BIN_NS = 5_000  # 5 µs bins, Table 2.1
HIST_BINS = 400  # 0-2 ms, plus one overflow bin
FAULT_TEXT = 160
LINK_FIELDS = tuple(LinkCounters().as_dict())
CLIENT_WORDS = ("estop", "heartbeat")  # ESTOP_WORD, HEARTBEAT_WORD
ESTOP_WORD, HEARTBEAT_WORD = 0, 1


class Mode(IntEnum):
    """Controller modes: the thesis's four (section 5.1.1) plus the rig's Initialise (3.4.1)."""

    HOLD = 0
    FOLLOW_TRACK = 1
    MANUAL_ACTUATE = 2
    TRACKING_ACTUATE = 3
    INITIALISE = 4


class Flag(IntFlag):
    ESTOP_LATCHED = 1
    ESTOP_INPUT = 2
    HOMED = 4
    UI_LOST = 8
    LINK_FAULT = 16
    REALTIME = 32
    MOVING = 64
    FAULT = 128
    PAUSED = 256  # feed hold on the move
    SETTLING = 512  # the move's path is over: it holds the end until in position (settle.py)
    REDUCED = 1024  # reduced speed, ISO 10218-1's T1 (control/rt/speed_cap.py); else automatic


def _align(n: int) -> int:
    return (n + 7) // 8 * 8


@dataclass(frozen=True)
class Status:
    """One consistent snapshot of the controller, published every tick.

    Positions in joint units (mm, deg); ``duty`` is the controller output in
    the joint's sense (percent), ``valve`` what the backend was sent. ``time_s``
    is the controller's clock since it started (simulated time in lockstep),
    ``wall_ns`` the monotonic clock when the snapshot was written.
    """

    tick: int
    time_s: float
    wall_ns: int
    mode: Mode
    flags: Flag
    move_id: int
    move_done: int
    move_total: int
    late_last_us: float
    late_max_us: float
    overruns: int
    compute_last_us: float
    compute_max_us: float
    compute_total_s: float
    io_total_s: float
    feed_override: float  # the operator's feed override, 0…1 (control/rt/feed.py)
    feed_rate: float  # the rate the path advances at now: ramps to the override, 0 in a hold
    supply_mpa: float  # hydraulic supply pressure, MPa; NaN when the backend cannot measure it
    position: tuple[float, ...]
    desired: tuple[float, ...]
    duty: tuple[float, ...]
    valve: tuple[float, ...]
    settle_s: tuple[float, ...]  # settling: s after the path's end each joint came in position
    raw: tuple[int, ...]
    glitches: tuple[int, ...]
    link: dict[str, int]
    fault: str

    @property
    def estop(self) -> bool:
        return bool(self.flags & Flag.ESTOP_LATCHED)

    @property
    def moving(self) -> bool:
        return bool(self.flags & Flag.MOVING)

    @property
    def homed(self) -> bool:
        return bool(self.flags & Flag.HOMED)

    @property
    def paused(self) -> bool:
        return bool(self.flags & Flag.PAUSED)

    @property
    def speed_mode(self) -> str:
        """``reduced`` (T1: the tool at most 250 mm/s, each joint its jog_speed) or
        ``automatic`` (full speed): the controller's (``control/rt/speed_cap.py``)."""
        return "reduced" if self.flags & Flag.REDUCED else "automatic"

    @property
    def settling(self) -> bool:
        """The move's path is over and it waits to be in position (``docs/motion.md``)."""
        return bool(self.flags & Flag.SETTLING)


class StatusLayout:
    """The packed status record for ``n`` joints: its field order, encoding and decoding."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.struct = struct.Struct(
            f"<qqqiiqqqqqqqqqqddd{n}d{n}d{n}d{n}d{n}d{n}q{n}q{len(LINK_FIELDS)}q{FAULT_TEXT}s"
        )
        self._link = attrgetter(*LINK_FIELDS)
        self._fault = ("", b"")  # the last fault text and its bytes: it rarely changes

    def encode(self, tick: int, time_ns: int, wall_ns: int, mode: int, flags: int,
               move_id: int, move_done: int, move_total: int, latency: LatencyStats,
               feed: tuple[float, float], supply_mpa: float, position: list[float],
               desired: list[float],
               duty: list[float], valve: list[float], settle_s: list[float], raw: list[int],
               glitches: list[int], link: LinkCounters, fault: str) -> tuple:
        """The values of one record in struct order (the loop's ``publish``, every tick)."""
        if fault != self._fault[0]:
            self._fault = (fault, fault.encode()[:FAULT_TEXT])
        return (tick, time_ns, wall_ns, mode, flags, move_id, move_done, move_total,
                latency.late_ns, latency.late_max_ns, latency.overruns, latency.compute_ns,
                latency.compute_max_ns, latency.compute_total_ns, latency.io_total_ns, *feed,
                supply_mpa,
                *position, *desired, *duty, *valve, *settle_s, *raw, *glitches, *self._link(link),
                self._fault[1])

    def decode(self, values: tuple) -> Status:
        n = self.n
        (tick, time_ns, wall_ns, mode, flags, move_id, done, total,
         late_last, late_max, overruns, comp_last, comp_max, comp_total, io_total,
         feed_override, feed_rate, supply_mpa) = values[:18]
        arrays = values[18:18 + 7 * n]
        link = values[18 + 7 * n:18 + 7 * n + len(LINK_FIELDS)]
        fault = values[-1].rstrip(b"\0").decode("utf-8", "replace")
        return Status(
            tick=tick, time_s=time_ns / 1e9, wall_ns=wall_ns, mode=Mode(mode), flags=Flag(flags),
            move_id=move_id, move_done=done, move_total=total,
            late_last_us=late_last / 1e3, late_max_us=late_max / 1e3, overruns=overruns,
            compute_last_us=comp_last / 1e3, compute_max_us=comp_max / 1e3,
            compute_total_s=comp_total / 1e9, io_total_s=io_total / 1e9,
            feed_override=feed_override, feed_rate=feed_rate, supply_mpa=supply_mpa,
            position=arrays[0:n], desired=arrays[n:2 * n], duty=arrays[2 * n:3 * n],
            valve=arrays[3 * n:4 * n], settle_s=arrays[4 * n:5 * n], raw=arrays[5 * n:6 * n],
            glitches=arrays[6 * n:7 * n],
            link=dict(zip(LINK_FIELDS, link, strict=True)), fault=fault,
        )


class CoefficientLayout:
    """A coefficient set of eq. 5.1 packed for ``n`` joints, at most ``MAX_TAPS`` taps each."""

    def __init__(self, n: int) -> None:
        self.n = n
        joint = f"{MAX_TAPS}di{MAX_TAPS}didddd"
        self.struct = struct.Struct("<" + joint * n + f"{MAX_TAPS}didddd")

    def encode(self, c: Coefficients) -> tuple:
        values: list = []
        for j in range(self.n):
            values += [*_padded(c.kp[j], f"kp[{j}]"), len(c.kp[j])]
            values += [*_padded(c.w[j], f"w[{j}]"), len(c.w[j])]
            values += [c.ki[j], c.kd[j], c.kv[j] if c.kv else 0.0,
                       c.deadband[j] if c.deadband else 0.0]
        values += [*_padded(c.filter, "filter"), len(c.filter)]
        values += [c.filter_divisor, c.integral_limit, c.duty_limit, c.integral_separation]
        return tuple(values)

    def decode(self, values: tuple, name: str) -> Coefficients:
        per_joint = 2 * MAX_TAPS + 6
        kp, w, ki, kd, kv, deadband = [], [], [], [], [], []
        for j in range(self.n):
            v = values[j * per_joint:(j + 1) * per_joint]
            kp.append(tuple(v[:v[MAX_TAPS]]))
            w.append(tuple(v[MAX_TAPS + 1:MAX_TAPS + 1 + v[2 * MAX_TAPS + 1]]))
            ki.append(v[2 * MAX_TAPS + 2])
            kd.append(v[2 * MAX_TAPS + 3])
            kv.append(v[2 * MAX_TAPS + 4])
            deadband.append(v[2 * MAX_TAPS + 5])
        tail = values[self.n * per_joint:]
        return Coefficients(
            name=name, note=name, kp=tuple(kp), ki=tuple(ki), kd=tuple(kd), w=tuple(w),
            filter=tuple(tail[:tail[MAX_TAPS]]), filter_divisor=tail[MAX_TAPS + 1],
            integral_limit=tail[MAX_TAPS + 2], duty_limit=tail[MAX_TAPS + 3],
            integral_separation=tail[MAX_TAPS + 4],
            kv=tuple(kv) if any(kv) else (),
            deadband=tuple(deadband) if any(deadband) else (),
        )


def _padded(taps: tuple[float, ...], what: str) -> list[float]:
    if len(taps) > MAX_TAPS:
        raise ValueError(f"coefficient {what} has {len(taps)} taps; at most {MAX_TAPS} fit")
    return [*taps, *([0.0] * (MAX_TAPS - len(taps)))]


class ControlLayout:
    """Offsets of the control segment for ``n`` joints.

    header (64 B): magic, version, joint count, controller pid, then the status
    seqlock, the hold and track coefficient seqlocks, the histogram
    (``HIST_BINS + 1`` counts, then min, max, sum and count of lateness in ns), and
    the client's words: its E-stop count and its heartbeat (monotonic ns), each one
    aligned 8-byte store that the controller reads every tick, so neither waits on
    the command channel.
    """

    HEADER = struct.Struct("<4sIII")
    PID_OFFSET = 12

    def __init__(self, n: int) -> None:
        self.n = n
        self.status = StatusLayout(n)
        self.coefficients = CoefficientLayout(n)
        self.status_offset = 64
        self.hold_offset = _align(self.status_offset + 8 + self.status.struct.size)
        self.track_offset = _align(self.hold_offset + 8 + self.coefficients.struct.size)
        self.hist_offset = _align(self.track_offset + 8 + self.coefficients.struct.size)
        self.client_offset = self.hist_offset + 8 * (HIST_BINS + 1 + 4)
        self.size = self.client_offset + 8 * len(CLIENT_WORDS)

    def coefficient_offset(self, which: str) -> int:
        if which not in ("hold", "track"):
            raise ValueError(f"coefficient set must be 'hold' or 'track', got {which!r}")
        return self.hold_offset if which == "hold" else self.track_offset

    def write_header(self, buf: memoryview) -> None:
        self.HEADER.pack_into(buf, 0, CONTROL_MAGIC, LAYOUT_VERSION, self.n, 0)

    def check_header(self, buf: memoryview) -> None:
        magic, version, n, _ = self.HEADER.unpack_from(buf, 0)
        if magic != CONTROL_MAGIC or version != LAYOUT_VERSION or n != self.n:
            raise ValueError(f"control segment is {magic!r} v{version} for {n} joints; expected "
                             f"{CONTROL_MAGIC!r} v{LAYOUT_VERSION} for {self.n}")

    def client_words(self, buf: memoryview) -> memoryview:
        """The client's words as a ``q`` view, in ``CLIENT_WORDS`` order."""
        return buf[self.client_offset:self.client_offset + 8 * len(CLIENT_WORDS)].cast("q")

    def histogram(self, buf: memoryview) -> np.ndarray:
        """A (HIST_BINS + 5,) int64 view: counts, then min, max, sum, count."""
        return np.frombuffer(buf, np.int64, HIST_BINS + 5, self.hist_offset)


class MoveLayout:
    """A move segment: the recorded run, and all it needs to be saved by whoever outlives
    the move (``control/recovery.py``). The path the move follows is not here: it is sealed
    in a memory file of its own (``control/rt/sealed.py``), so no one can change it once sent.

    header (64 B): magic, version, samples N (the path's rows), joints J; at offset 24 the
    number of rows recorded so far (one aligned 8-byte store per tick); at 32 the
    metadata's length; at 40 S, the rows of the settle after the path (the controller
    records the hold of the path's end there until the move is in position: ``settle.py``).
    Then the status text the controller writes when the move ends (``STATUS_TEXT``
    bytes, empty while it runs), the move's timeline as JSON (its stalls, feed changes,
    feed holds and supply readings: ``TIMELINE_TEXT`` bytes, written by a controller whose
    client is gone, for whoever saves the run), the run's metadata as JSON (written by the
    client), and ``record (N + S, 1 + 3J)`` rows of ``t, desired..., actual..., duty...`` as
    float64.
    """

    HEADER = struct.Struct("<4sIQI")
    RECORDED_OFFSET = 24
    META_SIZE_OFFSET = 32
    SETTLE_ROWS_OFFSET = 40
    STATUS_OFFSET = 64
    STATUS_TEXT = 256
    TIMELINE_OFFSET = STATUS_OFFSET + STATUS_TEXT
    TIMELINE_TEXT = 256 * 1024  # a move's bounded timelines as JSON (control/rt/modes.py)

    def __init__(self, samples: int, n: int, meta_size: int = 0, settle_rows: int = 0) -> None:
        if samples < 1:
            raise ValueError("a move needs at least one sample")
        self.samples = samples
        self.settle_rows = settle_rows
        self.rows = samples + settle_rows  # the record's room: the path, then its settle
        self.n = n
        self.meta_size = meta_size
        self.row = struct.Struct(f"<{1 + 3 * n}d")
        self.target = struct.Struct(f"<{n}d")
        self.meta_offset = self.TIMELINE_OFFSET + self.TIMELINE_TEXT
        self.record_offset = _align(self.meta_offset + meta_size)
        self.size = self.record_offset + self.row.size * self.rows

    @classmethod
    def read_header(cls, buf: memoryview) -> MoveLayout:
        magic, version, samples, n = cls.HEADER.unpack_from(buf, 0)
        if magic != MOVE_MAGIC or version != LAYOUT_VERSION:
            raise ValueError(f"move segment is {magic!r} v{version}, expected {MOVE_MAGIC!r} "
                             f"v{LAYOUT_VERSION}")
        meta_size, settle_rows = struct.unpack_from("<QQ", buf, cls.META_SIZE_OFFSET)
        return cls(samples, n, meta_size, settle_rows)

    @classmethod
    def other_version(cls, buf: memoryview) -> int | None:
        """The layout version of a move segment a servodesk of another version wrote; None
        for this version's, or for what is no move segment at all."""
        if len(buf) < cls.HEADER.size:
            return None
        magic, version, _, _ = cls.HEADER.unpack_from(buf, 0)
        return version if magic == MOVE_MAGIC and version != LAYOUT_VERSION else None

    def write_header(self, buf: memoryview) -> None:
        self.HEADER.pack_into(buf, 0, MOVE_MAGIC, LAYOUT_VERSION, self.samples, self.n)
        struct.pack_into("<QQ", buf, self.META_SIZE_OFFSET, self.meta_size, self.settle_rows)

    def record(self, buf: memoryview) -> np.ndarray:
        return np.ndarray((self.rows, 1 + 3 * self.n), np.float64, buf, self.record_offset)

    def recorded(self, buf: memoryview) -> int:
        """Rows recorded so far."""
        return struct.unpack_from("<Q", buf, self.RECORDED_OFFSET)[0]

    def write_meta(self, buf: memoryview, meta: bytes) -> None:
        buf[self.meta_offset:self.meta_offset + len(meta)] = meta

    def read_meta(self, buf: memoryview) -> bytes:
        return bytes(buf[self.meta_offset:self.meta_offset + self.meta_size])

    def write_status(self, buf: memoryview, status: str) -> None:
        """How the move ended (the controller, once, when it ends); cut to fit."""
        text = status.encode()[:self.STATUS_TEXT - 1]
        buf[self.STATUS_OFFSET:self.STATUS_OFFSET + len(text) + 1] = text + b"\0"

    def write_timeline(self, buf: memoryview, timeline: dict[str, object]) -> None:
        """The ended move's timeline, for whoever saves its run after the controller (not in
        a tick: after the loop). ValueError if it does not fit (it is bounded to)."""
        text = json.dumps(timeline, separators=(",", ":")).encode()
        if len(text) >= self.TIMELINE_TEXT:
            raise ValueError(f"a timeline of {len(text)} bytes does not fit {self.TIMELINE_TEXT}")
        buf[self.TIMELINE_OFFSET:self.TIMELINE_OFFSET + len(text) + 1] = text + b"\0"

    def read_timeline(self, buf: memoryview) -> dict[str, list[list[float]]] | None:
        """The timeline a controller wrote, or None (written by nobody, or unreadable)."""
        raw = bytes(buf[self.TIMELINE_OFFSET:self.TIMELINE_OFFSET + self.TIMELINE_TEXT])
        text = raw.split(b"\0", 1)[0]
        try:
            timeline = json.loads(text) if text else None
        except ValueError:
            return None
        return timeline if isinstance(timeline, dict) else None

    def read_status(self, buf: memoryview) -> str:
        """The ended move's status, or "" while it runs (or if it never ended)."""
        raw = bytes(buf[self.STATUS_OFFSET:self.STATUS_OFFSET + self.STATUS_TEXT])
        return raw.split(b"\0", 1)[0].decode("utf-8", "replace")


@dataclass(frozen=True)
class LatencyHistogram:
    """Wake-up lateness of the loop in 5 µs bins, as Table 2.1; the last bin holds ≥ 2 ms."""

    counts: np.ndarray
    ticks: int
    min_us: float
    max_us: float
    mean_us: float
    overruns: int
    bin_us: float = HIST_BIN_NS / 1e3

    @classmethod
    def from_counters(cls, values: np.ndarray, overruns: int) -> LatencyHistogram:
        counts = values[:HIST_BINS + 1]
        low, high, total, ticks = (int(v) for v in values[HIST_BINS + 1:HIST_BINS + 5])
        return cls(counts=counts, ticks=ticks, min_us=low / 1e3, max_us=high / 1e3,
                   mean_us=total / ticks / 1e3 if ticks else 0.0, overruns=overruns)

    def percentile(self, p: float) -> float:
        """Upper edge (µs) of the bin holding the ``p``-th percentile of lateness."""
        if not self.ticks:
            return 0.0
        index = int(np.searchsorted(np.cumsum(self.counts), p / 100 * self.ticks))
        return (min(index, HIST_BINS) + 1) * self.bin_us

    def rows(self, up_to_us: float = 80.0) -> list[tuple[float, float, int]]:
        """``(from µs, to µs, ticks)`` rows up to ``up_to_us``, then one row for the rest."""
        edge = int(up_to_us // self.bin_us)
        rows = [(i * self.bin_us, (i + 1) * self.bin_us, int(self.counts[i])) for i in range(edge)]
        rows.append((edge * self.bin_us, float("inf"), int(self.counts[edge:].sum())))
        return rows
