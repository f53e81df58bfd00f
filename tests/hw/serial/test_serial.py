"""The serial backend against the emulated board in another process, over a real pty (and TCP).

Every test starts ``servodesk emulate`` (the simulator behind the board's
protocol) as a child process, reads the URL from its first line and drives
``SerialBackend`` the way the control loop does: ``read``, ``write``, once a
millisecond or so. Timeouts are generous: the machine is shared; the tests
check behaviour, not speed.
"""

from __future__ import annotations

import itertools
import os
import signal
import statistics
import time
from collections.abc import Callable, Iterator, Sequence

import pytest

from hw.backend import LinkCounters
from hw.gray import gray_to_binary
from hw.machine import Machine, load_machine
from hw.serial.backend import BoardClock, BoardError, SerialBackend
from hw.serial.emulator import FIRMWARE, EmulatedBoard, Faults
from hw.serial.frame import FrameWriter
from hw.serial.messages import (
    BOARD_TO_HOST,
    BoardConfig,
    Config,
    ConfigAck,
    Duty,
    Event,
    Flag,
    Heartbeat,
    MessageReader,
    MessageWriter,
    MsgType,
    Nak,
    NakReason,
    Report,
    Status,
)
from hw.sim.backend import SimBackend

PATIENT_S = 1.0  # link timeout of the tests that are not about it: a busy machine stalls processes
UNIMATE = load_machine("unimate2000b")


@pytest.fixture
def connect() -> Iterator[Callable[..., SerialBackend]]:
    opened: list[SerialBackend] = []

    def open_backend(url: str, machine: Machine = UNIMATE, **options: float) -> SerialBackend:
        options.setdefault("open_timeout_s", 5.0)
        backend = SerialBackend(machine, url, **options)
        backend.open()
        opened.append(backend)
        return backend

    try:
        yield open_backend
    finally:
        for backend in opened:
            backend.close()


def positions(machine: Machine, raw: Sequence[int]) -> list[float]:
    """Joint units from raw words, as the control loop converts them."""
    q: list[float] = []
    for joint, word in zip(machine.joints, raw, strict=True):
        count = gray_to_binary(word) if machine.encoder_kind == "gray" else word
        value = joint.encoder.gradient * count + joint.encoder.constant
        if joint.encoder.coupled_to is not None:
            value += joint.encoder.coupling * q[joint.encoder.coupled_to]
        q.append(value)
    return q


def settled(machine: Machine, readings: list[list[int]], last: int = 15) -> list[float]:
    """Per-joint median position of the last readings: robust to the encoders' wrong readings."""
    window = [positions(machine, r) for r in readings[-last:]]
    return [statistics.median(column) for column in zip(*window, strict=True)]


def drive(backend: SerialBackend, duty: Sequence[float], seconds: float) -> list[list[int]]:
    """Run a 1 kHz-ish loop: read, write ``duty``; return every reading."""
    raw = [0] * backend.machine.n_joints
    readings = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        backend.read(raw)
        readings.append(list(raw))
        backend.write(duty)
        time.sleep(0.001)
    return readings


def drive_through_stalls(backend: SerialBackend, duty: Sequence[float],
                         seconds: float) -> list[list[int]]:
    """``drive``, again after a reconnect if a stall of this host process tripped the watchdog."""
    for _ in range(5):
        readings = drive(backend, duty, seconds)
        if backend.fault == "":
            return readings
        backend.reconnect()
    pytest.fail(f"the host kept stalling longer than the watchdog: {backend.fault}")


def listen(backend: SerialBackend, seconds: float) -> list[list[int]]:
    """Read without commanding anything (the host has stopped sending duty)."""
    raw = [0] * backend.machine.n_joints
    readings = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        backend.read(raw)
        readings.append(list(raw))
        time.sleep(0.002)
    return readings


def until(predicate: Callable[[], bool], backend: SerialBackend, duty: Sequence[float],
          timeout_s: float = 10.0) -> bool:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        drive(backend, duty, 0.02)
        if predicate():
            return True
    return False


# -- round trips -------------------------------------------------------------------------------


def test_board_time_places_late_replies_when_they_were_latched() -> None:
    """Samples 1 ms apart on the board, the second delivered 9 ms late, then the board's u32
    microsecond clock wrapping: host times follow the board's spacing, never the arrival."""
    clock = BoardClock()
    start = 5_000_000_000
    t0 = 2**32 - 1500  # 1.5 ms before the board's clock wraps
    assert clock.host_ns(t0, start + 200_000) == start + 200_000
    late = clock.host_ns(t0 + 1000, start + 10_200_000)  # latched 1 ms later, arrived 10 ms
    assert late == start + 1_200_000
    wrapped = clock.host_ns((t0 + 2000) % 2**32, start + 2_150_000)  # a faster delivery
    assert wrapped == start + 2_150_000  # 2 ms after the first latch, on the new best delay
    assert clock.host_ns((t0 + 2000) % 2**32, start + 3_000_000) == wrapped  # a repeat: same


def test_open_configures_the_board_and_reads_it(emulator, connect) -> None:
    board = emulator()
    backend = connect(board.url)
    assert backend.firmware == FIRMWARE
    assert backend.fault == "" and not backend.estop
    assert backend.board_flags & Flag.HELD  # nothing moves before the first command
    raw = [0] * 6
    backend.read(raw)
    assert raw == list(backend.last_report.words)
    assert all(0 <= w < 2**13 for w in raw)
    assert backend.machine.check_targets(positions(UNIMATE, raw))


def test_each_joint_moves_the_way_its_duty_and_polarity_say(emulator, connect) -> None:
    board = emulator("--seed", "3")
    backend = connect(board.url, watchdog_s=PATIENT_S)
    duty = [40.0, -40.0, 40.0, -40.0, 40.0, -40.0]
    before = settled(UNIMATE, drive(backend, [0.0] * 6, 0.1))
    after = settled(UNIMATE, drive(backend, duty, 0.6))
    assert backend.fault == ""
    assert not backend.board_flags & Flag.HELD
    for joint, d, q0, q1 in zip(UNIMATE.joints, duty, before, after, strict=True):
        expected = 1 if d * joint.polarity > 0 else -1
        assert (q1 - q0) * expected > 2 * joint.tolerance, (
            f"{joint.name}: {q0:.2f} -> {q1:.2f}{joint.symbol} for duty {d:+g} %, "
            f"polarity {joint.polarity:+d}")
    c = backend.counters
    assert c.frames_rx > 100 and c.crc_errors == c.truncated == c.out_of_order == 0
    summary = board.stop()
    assert summary["applied"] > 100 and summary["crc_errors"] == 0


def test_tcp_url_serves_the_rig_too(emulator, connect) -> None:
    rig = load_machine("rig")
    board = emulator("--machine", "rig", "--tcp", "0")
    assert board.url.startswith("socket://127.0.0.1:")
    backend = connect(board.url, rig, watchdog_s=PATIENT_S)
    start = positions(rig, drive(backend, [0.0], 0.1)[-1])[0]
    raised = positions(rig, drive(backend, [30.0], 0.5)[-1])[0]
    assert raised - start > 10.0  # mm: positive duty lifts the ram (polarity +1)
    assert backend.fault == ""


# -- the board's watchdog ----------------------------------------------------------------------


def test_watchdog_closes_the_valves_when_commands_stop(emulator, connect) -> None:
    board = emulator("--glitch-scale", "0")
    backend = connect(board.url)
    moving = drive_through_stalls(backend, [0.0, 45.0, 0.0, 0.0, 0.0, 0.0], 0.5)
    last_answer = backend.last_report
    trips, losses = backend.counters.watchdog_trips, backend.counters.link_lost
    assert not backend.board_flags & Flag.HELD

    resting = listen(backend, 0.4)   # commands stop: the board trips, the joint comes to rest
    still = listen(backend, 0.4)

    assert backend.board_flags & (Flag.HELD | Flag.WATCHDOG) == Flag.HELD | Flag.WATCHDOG
    status = backend.last_status
    assert status is not None and status.event == Event.WATCHDOG_TRIP
    assert 50 <= status.detail <= 150, f"tripped {status.detail} ms after the last command"
    assert 50_000 <= status.t_us - last_answer.t_us <= 150_000
    assert "watchdog closed the valves" in backend.fault
    assert backend.counters.watchdog_trips == trips + 1
    assert backend.counters.link_lost == losses

    moved = abs(positions(UNIMATE, moving[-1])[1] - positions(UNIMATE, moving[-50])[1])
    drift = abs(positions(UNIMATE, still[-1])[1] - positions(UNIMATE, resting[-1])[1])
    assert moved > 0.5 and drift < 0.2, (moved, drift)  # degrees, over 50 readings vs 0.4 s

    backend.reconnect()
    assert backend.fault == ""
    drive(backend, [0.0] * 6, 0.05)
    assert not backend.board_flags & (Flag.HELD | Flag.WATCHDOG)


# -- late answers: the same sample, and a new one asked for ------------------------------------


def test_a_read_with_nothing_sent_since_the_last_asks_the_board_for_a_new_sample(
        emulator, connect) -> None:
    """A resync reads the joints several times before the loop writes anything: each read
    with nothing sent since the one before asks for a new sample (a HEARTBEAT), so that it
    does not re-read the words it has; a read with a command's answer pending asks nothing."""
    board = emulator("--glitch-scale", "0")
    backend = connect(board.url)
    raw = [0] * 6
    backend.read(raw)  # open's own HEARTBEAT was the last frame: its answer is in hand
    first, sent = backend.sample_ns, backend.counters.frames_tx
    backend.read(raw)
    assert backend.counters.frames_tx == sent + 1, "a read with nothing sent asks for a sample"
    assert backend.wait_reply(PATIENT_S)
    backend.read(raw)
    assert backend.sample_ns != first
    backend.write([0.0] * 6)
    sent = backend.counters.frames_tx
    backend.read(raw)
    assert backend.counters.frames_tx == sent, "the command's answer is the new sample"


def test_answers_held_back_leave_the_words_and_their_sample_time_as_they_were(
        emulator, connect) -> None:
    """The board holds its answers back 20 ms every 50 ms (``--hold-replies``): every read
    that finds no new answer returns the words and ``sample_ns`` of the read before (the
    same sample, which the encoder input then does not judge again), and the answers held
    back arrive at once after."""
    board = emulator("--glitch-scale", "0", "--hold-replies", "20", "--fault-every", "0.05")
    backend = connect(board.url, watchdog_s=PATIENT_S)
    raw = [0] * 6
    backend.read(raw)
    same = new = 0
    end = time.monotonic() + 0.5
    while time.monotonic() < end:
        before, late = (backend.sample_ns, list(raw)), backend.late_replies
        backend.read(raw)
        if backend.sample_ns == before[0]:
            assert raw == before[1]
            same += 1
        else:
            new += 1
        assert backend.late_replies == late or backend.sample_ns == before[0]
        backend.write([0.0] * 6)
        time.sleep(0.001)
    assert backend.fault == ""
    assert same > 20 and new > 20, (same, new)


def test_the_board_flips_a_word_then_holds_its_answers_back_and_sends_them_at_once() -> None:
    """``Faults.flip_word`` and ``hold_ms``, in process: 10 ms after the CONFIG one REPORT has
    bit 11 of Rotate's word flipped; the answers after it come only when the 5 ms hold is
    over, all at once; the next beat is 10 ms on."""
    bench = BoardBench(Faults(flip_word=(1, 11), hold_ms=5.0, fault_every_s=0.01))
    bench.send(Config(bench.config))
    (clean,) = bench.send(Duty((0,) * 6, clear=True), 0.001)
    (flipped,) = bench.send(Duty((0,) * 6), 0.0105)
    assert (flipped.words[1] ^ clean.words[1]) & (1 << 11)
    assert flipped.words[:1] + flipped.words[2:] == clean.words[:1] + clean.words[2:]
    assert bench.send(Duty((0,) * 6), 0.012) == []
    assert bench.send(Duty((0,) * 6), 0.015) == []
    assert bench.board.next_event_ns(round(0.015e9)) == round(0.0155e9)  # wake to send them
    held = bench.poll(0.0156)
    assert [type(m) for m in held] == [Report, Report]
    assert [m.echo_seq for m in held] == [3, 4]
    (after,) = bench.send(Duty((0,) * 6), 0.016)
    assert after.words[1] == clean.words[1]
    assert (bench.board.flipped, bench.board.holds) == (1, 1)


def test_the_first_answer_after_every_configuration_can_be_made_wrong() -> None:
    """``Faults.flip_first``: the first REPORT after each CONFIG has the bit flipped, and only
    that one (a resync's first reading, with none before it to judge it by)."""
    bench = BoardBench(Faults(flip_first=(3, 11)))
    for at_s in (0.0, 0.1):
        bench.send(Config(bench.config), at_s)
        (first,) = bench.send(Heartbeat(), at_s + 0.001)
        (second,) = bench.send(Heartbeat(), at_s + 0.002)
        assert (first.words[3] ^ second.words[3]) == 1 << 11
    assert bench.board.flipped == 2


# -- corruption, silence, a vanished board ---------------------------------------------------


def test_corrupted_frames_are_counted_and_never_acted_on(emulator, connect) -> None:
    """One frame in five corrupted each way, driven until each side has counted more than
    ten (each damaged frame is judged alone: a fixed 1.5 s drive showed nothing more): none
    was acted on, no reading jumps."""
    board = emulator("--corrupt-rate", "0.2", "--corrupt-rx-rate", "0.2", "--seed", "5",
                     "--glitch-scale", "0")  # the encoders' own wrong readings would blur this
    backend = connect(board.url, watchdog_s=PATIENT_S)
    c = backend.counters
    readings: list[list[int]] = []
    end = time.monotonic() + 10.0
    while not (c.crc_errors > 10 and backend.last_report.rx_errors > 10):
        assert time.monotonic() < end, (c.crc_errors, backend.last_report.rx_errors)
        readings += drive(backend, [0.0] * 6, 0.05)

    assert backend.fault == ""  # no corrupted command was NAKed or applied, no report forged
    assert c.out_of_order == 0  # and the board saw the host's frames garbled too (rx_errors)
    counts = [[gray_to_binary(w) for w in r] for r in readings]
    steps = [abs(a - b) for prev, cur in itertools.pairwise(counts)
             for a, b in zip(prev, cur, strict=True)]
    assert max(steps) <= 2, "a reading jumped: a corrupted report was taken as valid"

    summary = board.stop()
    assert summary["crc_errors"] + summary["truncated"] > 10
    assert summary["naks"] == 0


def test_a_killed_emulator_is_a_lost_link_with_the_last_readings_kept(emulator, connect) -> None:
    board = emulator()
    backend = connect(board.url, watchdog_s=PATIENT_S)
    last = drive(backend, [0.0] * 6, 0.2)[-1]
    # the killed emulator's pty number stays taken while this is open: the reconnect finds the
    # port gone, not another test's terminal opened meanwhile under the same number
    held = os.open(board.url, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    try:
        board.kill()
        assert until(lambda: backend.fault != "", backend, [0.0] * 6)
        assert backend.fault.startswith("link lost: ")
        assert backend.counters.link_lost == 1
        raw = [0] * 6
        backend.read(raw)
        assert raw == last
        drive(backend, [10.0] * 6, 0.05)  # writing to a lost link is harmless
        assert backend.counters.link_lost == 1
        with pytest.raises(BoardError, match="cannot open"):
            backend.reconnect()
    finally:
        os.close(held)
    assert backend.fault.startswith("link lost: reconnect failed after ")


def test_a_silent_board_is_a_lost_link(emulator, connect) -> None:
    board = emulator("--silent-after", "0.3")
    backend = connect(board.url, watchdog_s=PATIENT_S)
    assert until(lambda: backend.fault != "", backend, [0.0] * 6)
    assert backend.fault.startswith("link lost: no frame from the I/O board for ")
    assert backend.counters.link_lost == 1
    backend.open_timeout_s = 0.5
    with pytest.raises(BoardError, match=r"no I/O board answered on .* within"):
        backend.reconnect()


def test_no_board_on_the_port_is_a_clear_error() -> None:
    master, slave = os.openpty()
    try:
        path = os.ttyname(slave)
        backend = SerialBackend(UNIMATE, path, open_timeout_s=0.05)
        with pytest.raises(BoardError) as info:
            backend.open()
        assert str(info.value) == (f"no I/O board answered on {path} within 0.05 s: "
                                   "check the port and that the board is powered")
    finally:
        os.close(master)
        os.close(slave)
    with pytest.raises(BoardError, match="cannot open /dev/nonexistent-servodesk"):
        SerialBackend(UNIMATE, "/dev/nonexistent-servodesk").open()


# -- the E-stop -------------------------------------------------------------------------------


def test_estop_closes_the_valves_and_rearms_only_on_a_zero_command(emulator, connect) -> None:
    board = emulator("--glitch-scale", "0")
    backend = connect(board.url, watchdog_s=PATIENT_S)
    duty = [0.0, 45.0, 0.0, 0.0, 0.0, 0.0]
    drive(backend, duty, 0.1)
    board.send(signal.SIGUSR1)
    assert until(lambda: backend.estop, backend, duty)
    assert backend.board_flags & Flag.HELD
    assert backend.last_status.event == Event.ESTOP_PRESSED
    drive(backend, duty, 0.2)
    held = [positions(UNIMATE, r)[1] for r in drive(backend, duty, 0.3)]
    assert max(held) - min(held) < 0.2  # degrees: duty is not applied while pressed

    board.send(signal.SIGUSR2)
    assert until(lambda: not backend.estop, backend, duty)
    drive(backend, duty, 0.1)
    assert backend.board_flags & Flag.HELD  # released, but a moving command does not re-arm
    assert until(lambda: not backend.board_flags & Flag.HELD, backend, [0.0] * 6)
    assert backend.fault == ""


# -- the board's refusals, in process (no transport needed) -------------------------------------


class BoardBench:
    """An ``EmulatedBoard`` on the real simulator, fed frames directly."""

    def __init__(self, faults: Faults | None = None) -> None:
        self.board = EmulatedBoard(SimBackend(UNIMATE, glitch_scale=0.0), faults=faults)
        self.host = MessageWriter()
        self.answers = MessageReader(LinkCounters(), BOARD_TO_HOST)
        self.config = BoardConfig.from_machine(UNIMATE, 0.05, 0.02)

    def send(self, message: object, at_s: float = 0.0) -> list[object]:
        out = self.board.receive(self.host.encode(message), round(at_s * 1e9))
        return [m for _, m in self.answers.feed(out)]

    def poll(self, at_s: float) -> list[object]:
        return [m for _, m in self.answers.feed(self.board.poll(round(at_s * 1e9)))]


def test_the_board_refuses_what_it_must_and_applies_none_of_it() -> None:
    bench = BoardBench()
    assert bench.send(Duty((0,) * 6)) == [Nak(0, MsgType.DUTY, NakReason.NOT_CONFIGURED)]
    too_many = BoardConfig(**{**vars(bench.config), "n_joints": 7})
    assert bench.send(Config(too_many)) == [Nak(1, MsgType.CONFIG, NakReason.BAD_CONFIG)]
    (ack,) = bench.send(Config(bench.config))
    assert isinstance(ack, ConfigAck) and ack.config == bench.config
    assert bench.send(Duty((0,) * 5, clear=True)) == [
        Nak(3, MsgType.DUTY, NakReason.BAD_LENGTH)]
    assert bench.send(Duty((0, 0, 0, 0, 0, 10001), clear=True)) == [
        Nak(4, MsgType.DUTY, NakReason.DUTY_RANGE)]
    frame = FrameWriter(5).frame(0x44, b"")
    assert [m for _, m in bench.answers.feed(bench.board.receive(frame, 0))] == [
        Nak(5, 0x44, NakReason.UNKNOWN_TYPE)]
    assert bench.board.held and bench.board.applied == 0


def test_clear_is_refused_while_the_estop_is_pressed_and_heartbeats_feed_no_watchdog() -> None:
    bench = BoardBench()
    bench.send(Config(bench.config))
    bench.board.press_estop()
    (status,) = bench.poll(0.001)
    assert status == Status(Flag.ESTOP | Flag.HELD, Event.ESTOP_PRESSED, status.t_us)
    (report,) = bench.send(Duty((0,) * 6, clear=True), 0.002)
    assert report.flags & Flag.HELD and bench.board.applied == 0
    bench.board.release_estop()
    bench.poll(0.003)
    (report,) = bench.send(Duty((100,) * 6, clear=True), 0.004)
    assert not report.flags & Flag.HELD and bench.board.applied == 1
    bench.send(Heartbeat(), 0.030)
    (trip,) = [m for m in bench.poll(0.055) if isinstance(m, Status)]
    assert trip.event == Event.WATCHDOG_TRIP and trip.detail == 51
    assert trip.flags == Flag.HELD | Flag.WATCHDOG
