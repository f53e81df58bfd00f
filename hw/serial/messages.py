"""Messages of the I/O board protocol (docs/protocol.md, section 3) and their codecs.

Every message is a frozen record with its type code ``TYPE``, a ``pack_into``
that writes its payload (little-endian) and an ``unpack`` that reads it back or
returns ``None`` when the payload does not have the message's shape.

Duty is carried in units of 0.01 % (``DUTY_SCALE`` per percent), signed,
within ±``DUTY_MAX``; encoder words are raw, unsigned 32-bit; board times are
microseconds of a free-running, wrapping 32-bit counter.

``MessageWriter`` and ``MessageReader`` add the frame layer
(``hw.serial.frame``) and the sequence-number rules: each direction numbers its
frames with its own wrapping u16; a receiver accepts a frame only if its number
is newer than the last one accepted (modular difference 1…32767) and counts the
rest as out of order. A resynchronising type (CONFIG towards the board,
CONFIG_ACK towards the host) is always accepted and sets the new baseline.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable
from dataclasses import dataclass
from enum import IntEnum, IntFlag
from typing import ClassVar

from hw.backend import LinkCounters
from hw.machine import Machine
from hw.serial.frame import HEADER_SIZE, SEQ_MOD, FrameReader, FrameWriter, wire_size

PROTOCOL_VERSION = 1
DUTY_SCALE = 100
DUTY_MAX = 100 * DUTY_SCALE
MAX_JOINTS = 16


class MsgType(IntEnum):
    """Message type codes; bit 7 set means board to host."""

    CONFIG = 0x01
    DUTY = 0x02
    HEARTBEAT = 0x03
    CONFIG_ACK = 0x81
    REPORT = 0x82
    STATUS = 0x83
    NAK = 0x8F


class Flag(IntFlag):
    """Board status flags, carried in every REPORT and STATUS."""

    ESTOP = 0x01
    HELD = 0x02
    WATCHDOG = 0x04
    UNSOLICITED = 0x08


class Event(IntEnum):
    """Why the board sent a STATUS."""

    ESTOP_PRESSED = 1
    ESTOP_RELEASED = 2
    WATCHDOG_TRIP = 3


class NakReason(IntEnum):
    """Why the board rejected a frame that passed its CRC."""

    UNKNOWN_TYPE = 1
    BAD_LENGTH = 2
    NOT_CONFIGURED = 3
    BAD_CONFIG = 4
    DUTY_RANGE = 5


class EncoderKind(IntEnum):
    GRAY = 0
    QUADRATURE = 1


DUTY_CLEAR = 0x01

_CONFIG = struct.Struct("<BBBBHHIHH")
_CONFIG_ACK_HEAD = struct.Struct("<HHB")
_REPORT_HEAD = struct.Struct("<HIBH")
_STATUS = struct.Struct("<BBIH")
_NAK = struct.Struct("<HBB")


def _duty_struct(n: int) -> struct.Struct:
    return struct.Struct(f"<B{n}h")


def _words_struct(n: int) -> struct.Struct:
    return struct.Struct(f"<{n}I")


_DUTY = {n: _duty_struct(n) for n in range(1, MAX_JOINTS + 1)}
_WORDS = {n: _words_struct(n) for n in range(1, MAX_JOINTS + 1)}


@dataclass(frozen=True)
class BoardConfig:
    """What the host tells the board about the machine; echoed back in CONFIG_ACK.

    ``watchdog_ms``: the board closes every valve when no valid DUTY arrived for
    this long. ``heartbeat_ms``: period of unsolicited REPORTs while the host is
    quiet. ``pwm_period_ns``: valve PWM period. ``duty_step``: the board's
    duty resolution in 0.01 % units (100 = 1 %). ``settle_us``: time from
    selecting a multiplexed encoder to latching its word.
    """

    n_joints: int
    encoder_kind: int
    encoder_bits: int
    watchdog_ms: int
    heartbeat_ms: int
    pwm_period_ns: int
    duty_step: int
    settle_us: int
    version: int = PROTOCOL_VERSION

    SIZE: ClassVar[int] = _CONFIG.size

    @classmethod
    def from_machine(cls, machine: Machine, watchdog_s: float, heartbeat_s: float) -> BoardConfig:
        return cls(
            n_joints=machine.n_joints,
            encoder_kind=EncoderKind[machine.encoder_kind.upper()],
            encoder_bits=machine.encoder_bits,
            watchdog_ms=round(watchdog_s * 1e3),
            heartbeat_ms=round(heartbeat_s * 1e3),
            pwm_period_ns=round(machine.valve_period_us * 1e3),
            duty_step=round(machine.valve_resolution_pct * DUTY_SCALE),
            settle_us=min(round(machine.encoder_settle_s * 1e6), 0xFFFF),
        )

    def problem(self, channels: int) -> str:
        """Why a board with ``channels`` valve/encoder channels cannot run this; "" if it can."""
        checks = (
            (self.version == PROTOCOL_VERSION,
             f"protocol version {self.version}, board speaks {PROTOCOL_VERSION}"),
            (1 <= self.n_joints <= channels, f"{self.n_joints} joints, board has {channels}"),
            (self.encoder_kind in tuple(EncoderKind), f"encoder kind {self.encoder_kind}"),
            (1 <= self.encoder_bits <= 32, f"{self.encoder_bits} encoder bits"),
            (10 <= self.watchdog_ms <= 1000, f"watchdog {self.watchdog_ms} ms (10…1000)"),
            (1 <= self.heartbeat_ms < self.watchdog_ms,
             f"heartbeat {self.heartbeat_ms} ms (1…watchdog)"),
            (1 <= self.duty_step <= DUTY_MAX, f"duty step {self.duty_step}"),
        )
        return "; ".join(text for ok, text in checks if not ok)

    def pack_into(self, buf: bytearray, offset: int) -> int:
        _CONFIG.pack_into(buf, offset, self.version, self.n_joints, self.encoder_kind,
                          self.encoder_bits, self.watchdog_ms, self.heartbeat_ms,
                          self.pwm_period_ns, self.duty_step, self.settle_us)
        return _CONFIG.size

    @classmethod
    def unpack_from(cls, data: bytes, offset: int = 0) -> BoardConfig:
        (version, n, kind, bits, watchdog, heartbeat, period,
         step, settle) = _CONFIG.unpack_from(data, offset)
        return cls(n, kind, bits, watchdog, heartbeat, period, step, settle, version)


@dataclass(frozen=True)
class Config:
    """Host → board: configure (or reconfigure) the board; answered by CONFIG_ACK or NAK."""

    config: BoardConfig

    TYPE: ClassVar[int] = MsgType.CONFIG

    def pack_into(self, buf: bytearray, offset: int) -> int:
        return self.config.pack_into(buf, offset)

    @classmethod
    def unpack(cls, payload: bytes) -> Config | None:
        if len(payload) != BoardConfig.SIZE:
            return None
        return cls(BoardConfig.unpack_from(payload))


@dataclass(frozen=True)
class Duty:
    """Host → board: signed valve duty per joint in 0.01 % units; answered by a REPORT.

    ``clear`` asks the board to leave the held state (section 5) and apply this duty.
    """

    duty: tuple[int, ...]
    clear: bool = False

    TYPE: ClassVar[int] = MsgType.DUTY

    def pack_into(self, buf: bytearray, offset: int) -> int:
        codec = _DUTY[len(self.duty)]
        codec.pack_into(buf, offset, DUTY_CLEAR if self.clear else 0, *self.duty)
        return codec.size

    @classmethod
    def unpack(cls, payload: bytes) -> Duty | None:
        n, odd = divmod(len(payload) - 1, 2)
        if odd or n not in _DUTY:
            return None
        flags, *duty = _DUTY[n].unpack(payload)
        return cls(tuple(duty), bool(flags & DUTY_CLEAR))


@dataclass(frozen=True)
class Heartbeat:
    """Host → board: the host is alive but commands nothing; answered by a REPORT.

    It does not feed the valve watchdog: only a DUTY does.
    """

    TYPE: ClassVar[int] = MsgType.HEARTBEAT

    def pack_into(self, buf: bytearray, offset: int) -> int:
        return 0

    @classmethod
    def unpack(cls, payload: bytes) -> Heartbeat | None:
        return cls() if not payload else None


@dataclass(frozen=True)
class ConfigAck:
    """Board → host: the configuration now in force, answering the CONFIG ``echo_seq``."""

    echo_seq: int
    firmware: int
    channels: int
    config: BoardConfig

    TYPE: ClassVar[int] = MsgType.CONFIG_ACK

    def pack_into(self, buf: bytearray, offset: int) -> int:
        _CONFIG_ACK_HEAD.pack_into(buf, offset, self.echo_seq, self.firmware, self.channels)
        return _CONFIG_ACK_HEAD.size + self.config.pack_into(buf, offset + _CONFIG_ACK_HEAD.size)

    @classmethod
    def unpack(cls, payload: bytes) -> ConfigAck | None:
        if len(payload) != _CONFIG_ACK_HEAD.size + BoardConfig.SIZE:
            return None
        echo, firmware, channels = _CONFIG_ACK_HEAD.unpack_from(payload)
        return cls(echo, firmware, channels,
                   BoardConfig.unpack_from(payload, _CONFIG_ACK_HEAD.size))


@dataclass(frozen=True)
class Report:
    """Board → host: raw encoder words per joint, latched at board time ``t_us``.

    ``echo_seq`` is the host frame this answers (with ``Flag.UNSOLICITED`` set,
    the last host frame accepted). ``rx_errors`` counts, wrapping at 2¹⁶, the
    host frames the board discarded (CRC, truncated, out of order).
    """

    echo_seq: int
    t_us: int
    flags: int
    rx_errors: int
    words: tuple[int, ...]

    TYPE: ClassVar[int] = MsgType.REPORT

    def pack_into(self, buf: bytearray, offset: int) -> int:
        _REPORT_HEAD.pack_into(buf, offset, self.echo_seq, self.t_us, self.flags, self.rx_errors)
        words = _WORDS[len(self.words)]
        words.pack_into(buf, offset + _REPORT_HEAD.size, *self.words)
        return _REPORT_HEAD.size + words.size

    @classmethod
    def unpack(cls, payload: bytes) -> Report | None:
        n, odd = divmod(len(payload) - _REPORT_HEAD.size, 4)
        if odd or n not in _WORDS:
            return None
        echo, t_us, flags, rx_errors = _REPORT_HEAD.unpack_from(payload)
        return cls(echo, t_us, flags, rx_errors, _WORDS[n].unpack_from(payload, _REPORT_HEAD.size))


@dataclass(frozen=True)
class Status:
    """Board → host, unsolicited: an E-stop edge or a watchdog trip, as it happens.

    ``detail`` for WATCHDOG_TRIP: milliseconds since the last valid DUTY.
    """

    flags: int
    event: int
    t_us: int
    detail: int = 0

    TYPE: ClassVar[int] = MsgType.STATUS

    def pack_into(self, buf: bytearray, offset: int) -> int:
        _STATUS.pack_into(buf, offset, self.flags, self.event, self.t_us, self.detail)
        return _STATUS.size

    @classmethod
    def unpack(cls, payload: bytes) -> Status | None:
        return cls(*_STATUS.unpack(payload)) if len(payload) == _STATUS.size else None


@dataclass(frozen=True)
class Nak:
    """Board → host: host frame ``echo_seq`` of type ``rejected_type`` is refused for ``reason``."""

    echo_seq: int
    rejected_type: int
    reason: int

    TYPE: ClassVar[int] = MsgType.NAK

    def pack_into(self, buf: bytearray, offset: int) -> int:
        _NAK.pack_into(buf, offset, self.echo_seq, self.rejected_type, self.reason)
        return _NAK.size

    @classmethod
    def unpack(cls, payload: bytes) -> Nak | None:
        return cls(*_NAK.unpack(payload)) if len(payload) == _NAK.size else None


@dataclass(frozen=True)
class Malformed:
    """A frame that passed its CRC but is no message this side accepts (never sent).

    The reader delivers it so the board can answer with a NAK; it is already
    counted as garbage.
    """

    type: int
    reason: int


Message = Config | Duty | Heartbeat | ConfigAck | Report | Status | Nak
Packet = tuple[int, Message | Malformed]
"""A received frame's sequence number and its message."""

MESSAGES: dict[int, type] = {
    m.TYPE: m for m in (Config, Duty, Heartbeat, ConfigAck, Report, Status, Nak)
}
HOST_TO_BOARD = frozenset({MsgType.CONFIG, MsgType.DUTY, MsgType.HEARTBEAT})
BOARD_TO_HOST = frozenset({MsgType.CONFIG_ACK, MsgType.REPORT, MsgType.STATUS, MsgType.NAK})


def seq_newer(seq: int, last: int) -> bool:
    """True if ``seq`` comes after ``last`` in the wrapping u16 sequence (by 1…32767)."""
    return 0 < (seq - last) % SEQ_MOD < SEQ_MOD // 2


class MessageWriter:
    """Encode messages into frames, numbering them; ``seq`` is the last number sent."""

    def __init__(self, first_seq: int = 0) -> None:
        self._frames = FrameWriter(first_seq)

    @property
    def seq(self) -> int:
        return self._frames.seq

    def encode(self, message: Message) -> bytes:
        """The wire bytes of ``message`` as the next frame, delimiter included."""
        n = message.pack_into(self._frames.body, HEADER_SIZE)
        return self._frames.finish(message.TYPE, n)


class MessageReader:
    """Stream decoder: bytes in, ``(seq, message)`` pairs out; never raises.

    ``accept`` is the set of types this side receives; any other frame, or one
    whose payload does not fit its type, counts as garbage and comes out as
    ``Malformed``. Frames older than the last accepted are dropped and counted
    as out of order. ``skipped`` counts sequence numbers that never arrived.
    """

    def __init__(self, counters: LinkCounters, accept: Iterable[int],
                 resync: Iterable[int] = ()) -> None:
        self.counters = counters
        self.accept = frozenset(accept)
        self.resync = frozenset(resync)
        self.skipped = 0
        self._frames = FrameReader(counters)
        self._last: int | None = None

    def reset(self) -> None:
        """Start over: drop any partial frame and accept the next sequence number as is."""
        self._frames.reset()
        self._last = None

    def feed(self, data: bytes | bytearray) -> list[Packet]:
        """Consume ``data``; return the accepted messages it completed, oldest first."""
        out: list[Packet] = []
        for frame in self._frames.feed(data):
            codec = MESSAGES.get(frame.type) if frame.type in self.accept else None
            message = codec.unpack(frame.payload) if codec is not None else None
            if message is None:
                self.counters.garbage_bytes += wire_size(len(frame.payload))
                reason = NakReason.UNKNOWN_TYPE if codec is None else NakReason.BAD_LENGTH
                out.append((frame.seq, Malformed(frame.type, reason)))
                continue
            if not self._in_order(frame.type, frame.seq):
                self.counters.out_of_order += 1
                continue
            self.counters.frames_rx += 1
            out.append((frame.seq, message))
        return out

    def _in_order(self, msg_type: int, seq: int) -> bool:
        last = self._last
        if last is None or msg_type in self.resync:
            self._last = seq
            return True
        if not seq_newer(seq, last):
            return False
        self.skipped += (seq - last) % SEQ_MOD - 1
        self._last = seq
        return True
