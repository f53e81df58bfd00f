"""Frames on the I/O board link: COBS byte stuffing, CRC-16 and a streaming splitter.

A frame on the wire is ``COBS(body) 0x00`` (docs/protocol.md, section 2), with

    body = type u8 | seq u16 little-endian | len u8 | payload (len bytes) | CRC-16 big-endian

The CRC is CRC-16/CCITT-FALSE (polynomial 0x1021, init 0xFFFF, not reflected,
no final xor), which is ``binascii.crc_hqx(data, 0xFFFF)``, computed over
type..payload and sent most significant byte first, so the CRC of a whole
intact body is 0. A body is at most 253 bytes, so COBS adds exactly one byte
and a frame is ``len + 8`` bytes on the wire, delimiter included.

``FrameReader`` never raises: every run of bytes that is not a good frame is
counted in a ``LinkCounters`` as a truncated frame, a CRC error or garbage.
"""

from __future__ import annotations

import binascii
import struct
from dataclasses import dataclass

from hw.backend import LinkCounters

HEADER = struct.Struct("<BHB")
HEADER_SIZE = HEADER.size
CRC_SIZE = 2
CRC_INIT = 0xFFFF
MAX_PAYLOAD = 247
MAX_BODY = HEADER_SIZE + MAX_PAYLOAD + CRC_SIZE
MAX_ENCODED = MAX_BODY + 1
DELIMITER = 0
SEQ_MOD = 1 << 16


def crc16(data: bytes | bytearray | memoryview, crc: int = CRC_INIT) -> int:
    """CRC-16/CCITT-FALSE of ``data`` (check value 0x29B1 for b"123456789")."""
    return binascii.crc_hqx(data, crc)


def wire_size(payload_len: int) -> int:
    """Bytes one frame with ``payload_len`` payload bytes takes on the wire, delimiter included."""
    return HEADER_SIZE + payload_len + CRC_SIZE + 2


def cobs_encode_into(src: bytes | bytearray | memoryview, dst: bytearray, start: int = 0) -> int:
    """COBS-encode ``src`` into ``dst`` from index ``start``; return the index after the last byte.

    ``dst`` must hold ``len(src) + len(src) // 254 + 1`` bytes from ``start``.
    """
    code_at = start
    out = start + 1
    code = 1
    for byte in src:
        if code == 0xFF:  # the block is full; open the next only now that more data follows
            dst[code_at] = code
            code_at = out
            out += 1
            code = 1
        if byte == 0:
            dst[code_at] = code
            code_at = out
            out += 1
            code = 1
        else:
            dst[out] = byte
            out += 1
            code += 1
    dst[code_at] = code
    return out


def cobs_encode(data: bytes | bytearray | memoryview) -> bytes:
    """COBS-encode ``data`` (no delimiter appended); the result contains no zero byte."""
    dst = bytearray(len(data) + len(data) // 254 + 1)
    return bytes(dst[: cobs_encode_into(data, dst)])


def cobs_decode(data: bytes | bytearray | memoryview) -> bytes | None:
    """Undo ``cobs_encode``; ``None`` if ``data`` is not a valid COBS encoding."""
    out = bytearray()
    i = 0
    n = len(data)
    while i < n:
        code = data[i]
        end = i + code
        if code == 0 or end > n:
            return None
        block = data[i + 1 : end]
        if 0 in block:
            return None
        out += block
        i = end
        if code != 0xFF and i < n:
            out.append(0)
    return bytes(out)


@dataclass(frozen=True)
class RawFrame:
    """A frame that passed the CRC and length checks; ``payload`` is not yet interpreted."""

    type: int
    seq: int
    payload: bytes


class FrameWriter:
    """Builds frames in preallocated buffers and numbers them with a wrapping u16 sequence.

    ``seq`` is the sequence number of the last frame built; the first frame is 0.
    """

    def __init__(self, first_seq: int = 0) -> None:
        self.seq = (first_seq - 1) % SEQ_MOD
        self.body = bytearray(MAX_BODY)
        self._wire = bytearray(MAX_ENCODED + 1)

    def next_seq(self) -> int:
        return (self.seq + 1) % SEQ_MOD

    def finish(self, msg_type: int, payload_len: int) -> bytes:
        """Frame the payload already written at ``body[HEADER_SIZE:]``; return the wire bytes."""
        if not 0 <= payload_len <= MAX_PAYLOAD:
            raise ValueError(f"payload of {payload_len} bytes does not fit a frame "
                             f"(at most {MAX_PAYLOAD})")
        self.seq = self.next_seq()
        body = self.body
        HEADER.pack_into(body, 0, msg_type, self.seq, payload_len)
        end = HEADER_SIZE + payload_len
        crc = crc16(memoryview(body)[:end])
        body[end] = crc >> 8
        body[end + 1] = crc & 0xFF
        n = cobs_encode_into(memoryview(body)[: end + CRC_SIZE], self._wire)
        self._wire[n] = DELIMITER
        return bytes(self._wire[: n + 1])

    def frame(self, msg_type: int, payload: bytes | bytearray) -> bytes:
        """Frame ``payload`` as one frame of type ``msg_type``."""
        if len(payload) > MAX_PAYLOAD:
            raise ValueError(f"payload of {len(payload)} bytes does not fit a frame "
                             f"(at most {MAX_PAYLOAD})")
        self.body[HEADER_SIZE : HEADER_SIZE + len(payload)] = payload
        return self.finish(msg_type, len(payload))


class FrameReader:
    """Split a byte stream at 0x00 delimiters into checked frames; never raises.

    Each rejected run of bytes counts once into ``counters``:

    - ``truncated``: the COBS stuffing is broken, the body is shorter than a
      header and CRC, or its size disagrees with its length field (bytes lost);
    - ``crc_errors``: the size is right but the CRC is not (bytes changed);
    - ``garbage_bytes``: a run longer than any frame without a delimiter
      (counted per byte, up to and excluding the next delimiter).

    Empty runs (consecutive delimiters) are legal padding and count nothing.
    """

    def __init__(self, counters: LinkCounters) -> None:
        self.counters = counters
        self._buf = bytearray()
        self._overrun = False

    def reset(self) -> None:
        """Forget any partial frame (after reopening the port)."""
        self._buf.clear()
        self._overrun = False

    def feed(self, data: bytes | bytearray) -> list[RawFrame]:
        """Consume ``data``; return the good frames it completed, in order."""
        frames: list[RawFrame] = []
        start = 0
        n = len(data)
        while start < n:
            stop = data.find(DELIMITER, start)
            if stop < 0:
                self._extend(data[start:])
                break
            self._extend(data[start:stop])
            self._end_of_frame(frames)
            start = stop + 1
        return frames

    def _extend(self, chunk: bytes | bytearray) -> None:
        if self._overrun:
            self.counters.garbage_bytes += len(chunk)
            return
        self._buf += chunk
        if len(self._buf) > MAX_ENCODED:
            self.counters.garbage_bytes += len(self._buf)
            self._buf.clear()
            self._overrun = True

    def _end_of_frame(self, frames: list[RawFrame]) -> None:
        if self._overrun:
            self._overrun = False
            return
        if not self._buf:
            return
        frame = self._check(self._buf)
        self._buf.clear()
        if frame is not None:
            frames.append(frame)

    def _check(self, encoded: bytearray) -> RawFrame | None:
        body = cobs_decode(encoded)
        if (body is None or len(body) < HEADER_SIZE + CRC_SIZE
                or len(body) != HEADER_SIZE + body[3] + CRC_SIZE):
            self.counters.truncated += 1
            return None
        if crc16(body) != 0:
            self.counters.crc_errors += 1
            return None
        msg_type, seq, length = HEADER.unpack_from(body)
        return RawFrame(msg_type, seq, body[HEADER_SIZE : HEADER_SIZE + length])
