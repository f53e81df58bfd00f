"""The I/O board codec: COBS, CRC, frames, messages, sequence rules; a decoder that never breaks."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hw.backend import LinkCounters
from hw.machine import load_machine
from hw.serial.frame import (
    MAX_ENCODED,
    FrameReader,
    FrameWriter,
    cobs_decode,
    cobs_encode,
    crc16,
    wire_size,
)
from hw.serial.messages import (
    BOARD_TO_HOST,
    HOST_TO_BOARD,
    BoardConfig,
    Config,
    ConfigAck,
    Duty,
    Event,
    Flag,
    Heartbeat,
    Malformed,
    MessageReader,
    MessageWriter,
    MsgType,
    Nak,
    NakReason,
    Report,
    Status,
    seq_newer,
)

CONFIG = BoardConfig(n_joints=6, encoder_kind=0, encoder_bits=13, watchdog_ms=50,
                     heartbeat_ms=20, pwm_period_ns=325_000, duty_step=100, settle_us=6000)

MESSAGES = [
    Config(CONFIG),
    Duty((1250, -300, 0, 0, 0, 10000), clear=True),
    Duty((-10000,)),
    Duty(tuple(range(-8, 8))),
    Heartbeat(),
    ConfigAck(echo_seq=65535, firmware=0x0100, channels=8, config=CONFIG),
    Report(echo_seq=7, t_us=2**32 - 1, flags=Flag.HELD | Flag.WATCHDOG, rx_errors=65535,
           words=(0, 1, 8191, 2**32 - 1, 0x0ABC, 12000)),
    Report(echo_seq=0, t_us=0, flags=0, rx_errors=0, words=(42,)),
    Status(flags=Flag.ESTOP | Flag.HELD, event=Event.ESTOP_PRESSED, t_us=123456, detail=0),
    Status(flags=Flag.HELD | Flag.WATCHDOG, event=Event.WATCHDOG_TRIP, t_us=1, detail=51),
    Nak(echo_seq=3, rejected_type=MsgType.DUTY, reason=NakReason.DUTY_RANGE),
]
BOTH_WAYS = HOST_TO_BOARD | BOARD_TO_HOST


def frames_of(messages: list, first_seq: int = 0) -> list[bytes]:
    writer = MessageWriter(first_seq)
    return [writer.encode(m) for m in messages]


def decode(data: bytes, accept: frozenset[int] = BOTH_WAYS) -> tuple[list, LinkCounters]:
    counters = LinkCounters()
    return MessageReader(counters, accept).feed(data), counters


# -- CRC and COBS -------------------------------------------------------------------------


def test_crc_is_ccitt_false_and_a_whole_body_checks_to_zero() -> None:
    assert crc16(b"123456789") == 0x29B1
    body = cobs_decode(frames_of([Heartbeat()])[0][:-1])
    assert body is not None and crc16(body) == 0


@pytest.mark.parametrize(("raw", "encoded"), [
    (b"", b"\x01"),
    (b"\x00", b"\x01\x01"),
    (b"\x00\x00", b"\x01\x01\x01"),
    (b"\x00\x11\x00", b"\x01\x02\x11\x01"),
    (b"\x11\x22\x00\x33", b"\x03\x11\x22\x02\x33"),
    (b"\x11\x22\x33\x44", b"\x05\x11\x22\x33\x44"),
    (b"\x11\x00\x00\x00", b"\x02\x11\x01\x01\x01"),
    (bytes(range(1, 255)), b"\xff" + bytes(range(1, 255))),
    (bytes(range(0, 255)), b"\x01\xff" + bytes(range(1, 255))),
    (bytes(range(1, 256)), b"\xff" + bytes(range(1, 255)) + b"\x02\xff"),
])
def test_cobs_matches_the_published_examples(raw: bytes, encoded: bytes) -> None:
    assert cobs_encode(raw) == encoded
    assert cobs_decode(encoded) == raw


@given(st.binary(max_size=1200))
def test_cobs_round_trips_and_never_emits_a_zero(data: bytes) -> None:
    encoded = cobs_encode(data)
    assert 0 not in encoded
    assert len(encoded) <= len(data) + len(data) // 254 + 1
    assert cobs_decode(encoded) == data


@pytest.mark.parametrize("bad", [b"\x05\x11", b"\x00", b"\x03\x11\x00"])
def test_cobs_rejects_broken_stuffing(bad: bytes) -> None:
    assert cobs_decode(bad) is None


# -- messages -------------------------------------------------------------------------------


@pytest.mark.parametrize("message", MESSAGES, ids=lambda m: type(m).__name__)
def test_every_message_type_round_trips(message: object) -> None:
    (frame,) = frames_of([message], first_seq=0xBEEF)
    assert frame.endswith(b"\x00") and 0 not in frame[:-1]
    packets, counters = decode(frame)
    assert packets == [(0xBEEF, message)]
    assert counters.frames_rx == 1


def test_frame_sizes_are_payload_plus_eight() -> None:
    duty, report = frames_of([Duty((0,) * 6), Report(0, 0, 0, 0, (0,) * 6)])
    assert (len(duty), len(report)) == (wire_size(13), wire_size(33)) == (21, 41)


def test_config_from_machine_carries_the_machine_file() -> None:
    config = BoardConfig.from_machine(load_machine("unimate2000b"), 0.05, 0.02)
    assert config == CONFIG
    assert config.problem(channels=8) == ""
    rig = BoardConfig.from_machine(load_machine("rig"), 0.05, 0.02)
    assert (rig.n_joints, rig.encoder_kind, rig.encoder_bits) == (1, 1, 16)


def test_config_problems_are_spelled_out() -> None:
    assert "6 joints, board has 4" in CONFIG.problem(channels=4)
    assert "watchdog 5 ms" in BoardConfig(1, 0, 13, 5, 2, 1, 100, 0).problem(channels=1)


def test_the_worked_example_of_the_protocol_document() -> None:
    (frame,) = frames_of([Duty((1250, -300, 0, 0, 0, 10000))], first_seq=0x0102)
    assert frame.hex(" ") == ("05 02 02 01 0d 05 e2 04 d4 fe 01 01 01 01 01 05 "
                              "10 27 b4 9b 00")


def test_wrong_direction_and_wrong_shape_come_out_malformed_and_count_as_garbage() -> None:
    writer = FrameWriter()
    stream = (frames_of([Duty((1, 2))])[0]                      # host type at the host
              + writer.frame(MsgType.REPORT, b"\x01\x02\x03")  # too short for a REPORT
              + writer.frame(0x55, b""))                       # unknown type
    packets, counters = decode(stream, accept=BOARD_TO_HOST)
    assert [m for _, m in packets] == [
        Malformed(MsgType.DUTY, NakReason.UNKNOWN_TYPE),
        Malformed(MsgType.REPORT, NakReason.BAD_LENGTH),
        Malformed(0x55, NakReason.UNKNOWN_TYPE),
    ]
    assert counters.garbage_bytes == len(stream)
    assert counters.frames_rx == 0


# -- the frame reader's accounting ------------------------------------------------------------


def test_bit_flip_in_a_data_byte_is_a_crc_error() -> None:
    frame = bytearray(frame_at(0x0101, Duty((0x0101,), clear=True)))
    assert frame[0] == len(frame) - 1  # one COBS block: every other byte is data
    frame[3] ^= 0x10
    packets, counters = decode(bytes(frame))
    assert packets == [] and counters.crc_errors == 1


def test_lost_bytes_are_a_truncated_frame_and_the_next_frame_still_arrives() -> None:
    first, second = frames_of([Report(1, 2, 0, 0, (3, 4)), Heartbeat()])
    packets, counters = decode(first[:10] + first[12:] + second)
    assert packets == [(1, Heartbeat())]
    assert counters.truncated == 1


def test_a_run_longer_than_any_frame_is_garbage_up_to_the_next_delimiter() -> None:
    (frame,) = frames_of([Heartbeat()])
    junk = b"\x01" * (MAX_ENCODED + 50)
    packets, counters = decode(junk + b"\x00" + frame)
    assert packets == [(0, Heartbeat())]
    assert counters.garbage_bytes == len(junk)


def test_empty_frames_are_padding() -> None:
    (frame,) = frames_of([Heartbeat()])
    packets, counters = decode(b"\x00\x00" + frame + b"\x00")
    assert packets == [(0, Heartbeat())]
    assert counters.as_dict() == LinkCounters(frames_rx=1).as_dict()


def test_feeding_byte_by_byte_gives_the_same_messages() -> None:
    stream = b"".join(frames_of(MESSAGES))
    reader = MessageReader(LinkCounters(), BOTH_WAYS)
    one_by_one = [p for i in range(len(stream)) for p in reader.feed(stream[i : i + 1])]
    assert one_by_one == decode(stream)[0]


def test_a_reset_reader_forgets_a_partial_frame() -> None:
    counters = LinkCounters()
    frames = FrameReader(counters)
    frames.feed(b"\x05\x01\x02")
    frames.reset()
    assert [f.type for f in frames.feed(frames_of([Heartbeat()])[0])] == [MsgType.HEARTBEAT]
    assert counters.truncated == 0


# -- sequence numbers --------------------------------------------------------------------------


def frame_at(seq: int, message: object = None) -> bytes:
    return MessageWriter(seq).encode(message or Heartbeat())


def test_out_of_order_and_duplicate_frames_are_dropped_and_counted() -> None:
    stream = b"".join(frame_at(s) for s in (5, 6, 4, 6, 9))
    reader = MessageReader(LinkCounters(), BOTH_WAYS)
    packets = reader.feed(stream)
    assert [seq for seq, _ in packets] == [5, 6, 9]
    assert reader.counters.out_of_order == 2
    assert reader.skipped == 2


def test_sequence_numbers_wrap_around() -> None:
    packets, counters = decode(b"".join(frame_at(s) for s in (65534, 65535, 0, 1)))
    assert [seq for seq, _ in packets] == [65534, 65535, 0, 1]
    assert counters.out_of_order == 0
    assert seq_newer(0, 65535) and seq_newer(32766, 65535)
    assert not seq_newer(32767, 65535) and not seq_newer(65535, 65535)


def test_a_resynchronising_type_is_accepted_whatever_its_number() -> None:
    reader = MessageReader(LinkCounters(), HOST_TO_BOARD, resync=(MsgType.CONFIG,))
    stream = frame_at(900) + frame_at(10, Config(CONFIG)) + frame_at(11) + frame_at(900)
    assert [seq for seq, _ in reader.feed(stream)] == [900, 10, 11, 900]
    assert reader.counters.out_of_order == 0


# -- nothing breaks the decoder, and nothing corrupted gets through ------------------------------


@pytest.mark.parametrize("message", MESSAGES, ids=lambda m: type(m).__name__)
def test_no_single_bit_flip_of_a_frame_is_ever_delivered(message: object) -> None:
    (frame,) = frames_of([message])
    for bit in range(8 * len(frame)):
        flipped = bytearray(frame)
        flipped[bit // 8] ^= 1 << (bit % 8)
        packets, _ = decode(bytes(flipped))
        assert all(isinstance(m, Malformed) for _, m in packets), f"bit {bit} got through"


@settings(max_examples=300)
@given(st.binary(max_size=2000), st.lists(st.integers(1, 500), max_size=8))
def test_random_bytes_never_raise_and_every_byte_is_accounted(data: bytes,
                                                               cuts: list[int]) -> None:
    reader = MessageReader(LinkCounters(), BOTH_WAYS)
    start = 0
    for cut in [*cuts, len(data)]:
        reader.feed(data[start : start + cut])
        start += cut
    reader.feed(data[start:])
    c = reader.counters
    assert min(c.crc_errors, c.truncated, c.garbage_bytes, c.out_of_order) >= 0


message_strategy = st.one_of(
    st.builds(Duty, st.lists(st.integers(-10000, 10000), min_size=1, max_size=16).map(tuple),
              st.booleans()),
    st.builds(Report, st.integers(0, 65535), st.integers(0, 2**32 - 1), st.integers(0, 255),
              st.integers(0, 65535),
              st.lists(st.integers(0, 2**32 - 1), min_size=1, max_size=16).map(tuple)),
    st.builds(Status, st.integers(0, 255), st.integers(0, 255), st.integers(0, 2**32 - 1),
              st.integers(0, 65535)),
    st.just(Heartbeat()),
)
mutation_strategy = st.one_of(
    st.just(("keep",)),
    st.tuples(st.just("flip"), st.lists(st.integers(0, 10_000), min_size=1, max_size=4)),
    st.tuples(st.just("cut_head"), st.integers(1, 60)),
    st.tuples(st.just("cut_tail"), st.integers(1, 60)),
    st.tuples(st.just("garbage"), st.binary(min_size=1, max_size=300)),
)


def mutate(frame: bytes, mutation: tuple) -> bytes:
    kind = mutation[0]
    if kind == "flip":
        out = bytearray(frame)
        for bit in mutation[1]:
            out[(bit // 8) % len(out)] ^= 1 << (bit % 8)
        return bytes(out)
    if kind == "cut_head":
        return frame[mutation[1]:]
    if kind == "cut_tail":
        return frame[: max(0, len(frame) - mutation[1])]
    if kind == "garbage":
        return mutation[1] + frame
    return frame


@settings(max_examples=300)
@given(st.lists(st.tuples(message_strategy, mutation_strategy), min_size=1, max_size=30))
def test_a_damaged_stream_delivers_only_what_was_sent_and_every_intact_frame(
        plan: list[tuple[object, tuple]]) -> None:
    """Bit flips, lost bytes and inserted garbage: no exception, no forged or reordered message.

    A frame whose own bytes are intact and that follows a delimiter is delivered.
    """
    sent = list(enumerate(m for m, _ in plan))
    frames = frames_of([m for m, _ in plan])
    stream = b""
    expected = []
    for (seq, message), frame, (_, mutation) in zip(sent, frames, plan, strict=True):
        damaged = mutate(frame, mutation)
        if damaged == frame and (not stream or stream.endswith(b"\x00")):
            expected.append((seq, message))
        stream += damaged
    packets, _ = decode(stream)
    delivered = [p for p in packets if not isinstance(p[1], Malformed)]
    assert set(expected) <= set(delivered)
    remaining = iter(sent)
    assert all(p in remaining for p in delivered), "a message was forged, repeated or reordered"
