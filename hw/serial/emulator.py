"""Device emulator: the I/O board of docs/protocol.md in software, in front of a simulated machine.

``EmulatedBoard`` is the board's firmware: the protocol state machine (configure,
hold, run, the 50 ms valve watchdog, the E-stop input) driving a plant backend
(normally ``hw.sim.backend.SimBackend`` in real time) through the same ``Backend``
interface the control loop uses. ``PtyPort`` and ``TcpPort`` carry its bytes;
``Emulator`` runs the loop: wait on the port until the next timed duty (a
watchdog deadline, a heartbeat), feed what arrived, send what the board says.

Fault injection (``Faults``) corrupts or drops frames and can make the board
fall silent, so the host's error handling is tested end to end. A garbled
frame from the host is counted (and reported in ``rx_errors``), never acted on.
"""

from __future__ import annotations

import contextlib
import os
import random
import select
import socket
import time
import tty
from collections.abc import Callable
from dataclasses import dataclass

from hw.backend import Backend, LinkCounters
from hw.serial.messages import (
    DUTY_MAX,
    DUTY_SCALE,
    HOST_TO_BOARD,
    BoardConfig,
    Config,
    ConfigAck,
    Duty,
    Event,
    Flag,
    Heartbeat,
    Malformed,
    Message,
    MessageReader,
    MessageWriter,
    MsgType,
    Nak,
    NakReason,
    Report,
    Status,
)

FIRMWARE = 0x0100
MAX_WAIT_NS = 1_000_000  # wake at least every millisecond to scan the encoders


@dataclass(frozen=True)
class Faults:
    """What goes wrong on purpose. Rates are probabilities per frame, 0…1.

    ``corrupt_rate``: board → host frames with one bit flipped.
    ``corrupt_rx_rate``: host → board frames with one bit flipped before the board decodes them.
    ``drop_rate``: board → host frames never sent.
    ``silent_after_s``: this long after the first CONFIG the board stops reading and
    writing (a hung board; its valve watchdog still closes the valves).

    A hostile board answers on time with words that lie:
    ``frozen_after_s``: this long after the first CONFIG every encoder word stays as it
    was (a stalled multiplexer, a cut cable reading a constant).
    ``stuck_bit``: (joint, bit, value): that bit of that joint's word always reads value.
    ``flood``: each REPORT is followed by this many more, valid, of the same words.

    Once every ``fault_every_s`` (the first that long after the first CONFIG):
    ``flip_word``: (joint, bit): one REPORT has that bit of that joint's word flipped (a
    wrong encoder word, once).
    ``hold_ms``: after that REPORT the board holds back its replies this long (it goes on
    applying DUTYs) and then sends them all at once: a host reading through the hold
    re-reads the words it had, so a flipped word just before is read again tick after tick.
    ``flip_first``: (joint, bit): the first REPORT after every CONFIG has that bit of that
    joint's word flipped, where the host has no reading before it to judge it by.
    """

    corrupt_rate: float = 0.0
    corrupt_rx_rate: float = 0.0
    drop_rate: float = 0.0
    silent_after_s: float | None = None
    frozen_after_s: float | None = None
    stuck_bit: tuple[int, int, int] | None = None
    flood: int = 0
    flip_word: tuple[int, int] | None = None
    hold_ms: float = 0.0
    fault_every_s: float = 1.0
    flip_first: tuple[int, int] | None = None

    @property
    def beats(self) -> bool:
        """Whether a flipped word or a hold comes every ``fault_every_s``."""
        return self.flip_word is not None or self.hold_ms > 0.0


class EmulatedBoard:
    """The board's firmware: bytes from the host in, bytes to the host out.

    Times are ``time.monotonic_ns()`` values passed in by the caller, so the
    state machine itself never reads a clock. With ``plant_time`` a REPORT is stamped
    with the plant's own latch time (``plant.sample_ns``) instead, as firmware stamps a
    reading when it latches it: for a real-time plant on the same monotonic clock (the
    ``Emulator``), where a stall between the caller's clock reading and the latch would
    otherwise date the words too early.
    """

    def __init__(self, plant: Backend, *, faults: Faults | None = None, seed: int = 0,
                 plant_time: bool = False) -> None:
        self.plant = plant
        self.plant_time = plant_time
        self.channels = plant.machine.n_joints
        self.faults = faults or Faults()
        self.counters = LinkCounters()
        self.reader = MessageReader(self.counters, HOST_TO_BOARD, resync=(MsgType.CONFIG,))
        self.writer = MessageWriter()
        self.config: BoardConfig | None = None
        self.held = True
        self.watchdog = False
        self.silent = False
        self.estop_button = False
        self.applied = 0
        self.naks = 0
        self.flipped = 0  # words flipped on purpose (Faults.flip_word, flip_first)
        self.holds = 0  # replies held back on purpose (Faults.hold_ms)
        self._rng = random.Random(seed)
        self._estop_reported = False
        self._duty_pct = [0.0] * self.channels
        self._raw = [0] * self.channels
        self._t0_ns: int | None = None
        self._last_duty_ns = 0
        self._last_tx_ns = 0
        self._last_host_seq = 0
        self._silent_at_ns: int | None = None
        self._frozen_at_ns: int | None = None
        self._frozen: tuple[int, ...] | None = None
        self._beat_at_ns: int | None = None  # when the next flipped word or hold is due
        self._flip_first = False  # the next REPORT is the first since a CONFIG
        self._hold_next = False  # hold back what follows the output now waiting
        self._held_until_ns = 0
        self._out = bytearray()

    # -- inputs -----------------------------------------------------------------

    def press_estop(self) -> None:
        """Press the E-stop button; the valves close at once (checked on the next ``poll``)."""
        self.estop_button = True

    def release_estop(self) -> None:
        """Release the E-stop button; the valves stay held until the host sends CLEAR."""
        self.estop_button = False

    def go_silent(self) -> None:
        """Stop reading and writing the link from now on."""
        self.silent = True

    @property
    def estop(self) -> bool:
        return self.estop_button or self.plant.estop

    @property
    def flags(self) -> int:
        return ((Flag.ESTOP if self.estop else 0) | (Flag.HELD if self.held else 0)
                | (Flag.WATCHDOG if self.watchdog else 0))

    @property
    def rx_errors(self) -> int:
        c = self.counters
        return (c.crc_errors + c.truncated + c.out_of_order) & 0xFFFF

    # -- the two entry points ---------------------------------------------------------

    def receive(self, data: bytes, now_ns: int) -> bytes:
        """Handle bytes from the host; return the bytes to send back."""
        if self.silent:
            return b""
        if self.faults.corrupt_rx_rate:
            data = self._corrupt_frames(data, self.faults.corrupt_rx_rate)
        for seq, message in self.reader.feed(data):
            self._handle(seq, message, now_ns)
        return self._take_output(now_ns)

    def poll(self, now_ns: int) -> bytes:
        """Timed duties: E-stop edges, the valve watchdog, heartbeats; return bytes to send."""
        if self._t0_ns is None:
            self._t0_ns = now_ns
        self._check_estop(now_ns)
        self._check_watchdog(now_ns)
        if self._silent_at_ns is not None and now_ns >= self._silent_at_ns:
            self.go_silent()
        if (self.config is not None and not self.silent
                and now_ns - self._last_tx_ns >= self.config.heartbeat_ms * 1_000_000):
            self._emit(self._report(self._last_host_seq, now_ns, unsolicited=True), now_ns)
        self.plant.read(self._raw)  # the board scans its encoders continuously
        return self._take_output(now_ns)

    def next_event_ns(self, now_ns: int) -> int:
        """When ``poll`` next has something to do (at most ``MAX_WAIT_NS`` ahead)."""
        deadline = now_ns + MAX_WAIT_NS
        if self.config is not None:
            deadline = min(deadline, self._last_tx_ns + self.config.heartbeat_ms * 1_000_000)
            if not self.held:
                deadline = min(deadline, self._last_duty_ns + self.config.watchdog_ms * 1_000_000)
        if now_ns < self._held_until_ns:
            deadline = min(deadline, self._held_until_ns)
        return deadline

    # -- host frames ----------------------------------------------------------------------

    def _handle(self, seq: int, message: Message | Malformed, now_ns: int) -> None:
        match message:
            case Malformed(type=msg_type, reason=reason):
                self._nak(seq, msg_type, reason, now_ns)
            case Config(config=config):
                self._configure(seq, config, now_ns)
            case Duty():
                self._duty(seq, message, now_ns)
            case Heartbeat():
                if self.config is None:
                    self._nak(seq, MsgType.HEARTBEAT, NakReason.NOT_CONFIGURED, now_ns)
                else:
                    self._last_host_seq = seq
                    self._emit(self._report(seq, now_ns), now_ns)

    def _configure(self, seq: int, config: BoardConfig, now_ns: int) -> None:
        if config.problem(self.channels):
            self._nak(seq, MsgType.CONFIG, NakReason.BAD_CONFIG, now_ns)
            return
        self.config = config
        self._close_valves()
        self.held = True
        self.watchdog = False
        self._last_host_seq = seq
        if self._silent_at_ns is None and self.faults.silent_after_s is not None:
            self._silent_at_ns = now_ns + round(self.faults.silent_after_s * 1e9)
        if self._frozen_at_ns is None and self.faults.frozen_after_s is not None:
            self._frozen_at_ns = now_ns + round(self.faults.frozen_after_s * 1e9)
        if self._beat_at_ns is None and self.faults.beats:
            self._beat_at_ns = now_ns + round(self.faults.fault_every_s * 1e9)
        self._flip_first = self.faults.flip_first is not None
        self._emit(ConfigAck(seq, FIRMWARE, self.channels, config), now_ns)

    def _duty(self, seq: int, message: Duty, now_ns: int) -> None:
        config = self.config
        if config is None:
            self._nak(seq, MsgType.DUTY, NakReason.NOT_CONFIGURED, now_ns)
            return
        if len(message.duty) != config.n_joints:
            self._nak(seq, MsgType.DUTY, NakReason.BAD_LENGTH, now_ns)
            return
        if any(not -DUTY_MAX <= u <= DUTY_MAX for u in message.duty):
            self._nak(seq, MsgType.DUTY, NakReason.DUTY_RANGE, now_ns)
            return
        self._last_duty_ns = now_ns
        self._last_host_seq = seq
        if self.held and message.clear and not self.estop:
            self.held = False
            self.watchdog = False
        if not self.held:
            step = config.duty_step
            for j, u in enumerate(message.duty):
                self._duty_pct[j] = round(u / step) * step / DUTY_SCALE
            self.plant.write(self._duty_pct)
            self.applied += 1
        report = self._report(seq, now_ns)
        for _ in range(1 + self.faults.flood):
            self._emit(report, now_ns)

    def _nak(self, seq: int, msg_type: int, reason: int, now_ns: int) -> None:
        self.naks += 1
        self._emit(Nak(seq, msg_type, reason), now_ns)

    # -- timed duties ------------------------------------------------------------------------

    def _check_estop(self, now_ns: int) -> None:
        pressed = self.estop
        if pressed and not self.held:
            self._close_valves()
            self.held = True
        if pressed != self._estop_reported:
            self._estop_reported = pressed
            if self.config is not None:
                event = Event.ESTOP_PRESSED if pressed else Event.ESTOP_RELEASED
                self._emit(Status(self.flags, event, self._t_us(now_ns)), now_ns)

    def _check_watchdog(self, now_ns: int) -> None:
        if self.held or self.config is None:
            return
        quiet_ns = now_ns - self._last_duty_ns
        if quiet_ns < self.config.watchdog_ms * 1_000_000:
            return
        self._close_valves()
        self.held = True
        self.watchdog = True
        self.counters.watchdog_trips += 1
        detail = min(quiet_ns // 1_000_000, 0xFFFF)
        self._emit(Status(self.flags, Event.WATCHDOG_TRIP, self._t_us(now_ns), detail), now_ns)

    def _close_valves(self) -> None:
        for j in range(self.channels):
            self._duty_pct[j] = 0.0
        self.plant.write(self._duty_pct)

    # -- output ------------------------------------------------------------------------------

    def _report(self, echo_seq: int, now_ns: int, unsolicited: bool = False) -> Report:
        assert self.config is not None
        self.plant.read(self._raw)
        flags = self.flags | (Flag.UNSOLICITED if unsolicited else 0)
        mask = (1 << self.config.encoder_bits) - 1  # a quadrature count wraps, two's complement
        words = self._lie(tuple(w & mask for w in self._raw[: self.config.n_joints]), now_ns)
        if self._beat_at_ns is not None and now_ns >= self._beat_at_ns:
            words = self._beat(words, now_ns)
        if self._flip_first and self.faults.flip_first is not None:
            self._flip_first = False
            words = self._flip(words, self.faults.flip_first)
        latched = self.plant.sample_ns if self.plant_time else now_ns
        return Report(echo_seq, self._t_us(latched), flags, self.rx_errors, words)

    def _lie(self, words: tuple[int, ...], now_ns: int) -> tuple[int, ...]:
        """The words a hostile board sends (``Faults.frozen_after_s``, ``stuck_bit``)."""
        if self._frozen_at_ns is not None and now_ns >= self._frozen_at_ns:
            if self._frozen is None:
                self._frozen = words
            return self._frozen
        if self.faults.stuck_bit is not None:
            joint, bit, value = self.faults.stuck_bit
            stuck = list(words)
            stuck[joint] = stuck[joint] | (1 << bit) if value else stuck[joint] & ~(1 << bit)
            return tuple(stuck)
        return words

    def _beat(self, words: tuple[int, ...], now_ns: int) -> tuple[int, ...]:
        """This REPORT's share of ``Faults.flip_word`` and ``hold_ms``: its word flipped, and
        the replies after it held back; the next beat ``fault_every_s`` on."""
        faults = self.faults
        assert self._beat_at_ns is not None
        every_ns = round(faults.fault_every_s * 1e9)
        self._beat_at_ns += every_ns * ((now_ns - self._beat_at_ns) // every_ns + 1)
        if faults.hold_ms > 0.0:
            self._hold_next = True
        return words if faults.flip_word is None else self._flip(words, faults.flip_word)

    def _flip(self, words: tuple[int, ...], where: tuple[int, int]) -> tuple[int, ...]:
        """``words`` with bit ``where[1]`` of joint ``where[0]``'s word flipped, counted."""
        joint, bit = where
        self.flipped += 1
        flipped = list(words)
        flipped[joint] ^= 1 << bit
        return tuple(flipped)

    def _t_us(self, now_ns: int) -> int:
        return ((now_ns - (self._t0_ns or now_ns)) // 1000) & 0xFFFFFFFF

    def _emit(self, message: Message, now_ns: int) -> None:
        frame = self.writer.encode(message)
        self._last_tx_ns = now_ns
        if self.silent or self._rng.random() < self.faults.drop_rate:
            return
        self.counters.frames_tx += 1
        if self._rng.random() < self.faults.corrupt_rate:
            frame = self._corrupt_frames(frame, 1.0)
        self._out += frame

    def _take_output(self, now_ns: int) -> bytes:
        """What to send now: nothing while replies are held back (``Faults.hold_ms``), then
        all that was held at once."""
        if now_ns < self._held_until_ns:
            return b""
        out = bytes(self._out)
        self._out.clear()
        if self._hold_next:
            self._hold_next = False
            self.holds += 1
            self._held_until_ns = now_ns + round(self.faults.hold_ms * 1e6)
        return out

    def _corrupt_frames(self, data: bytes, rate: float) -> bytes:
        """Flip one random bit in each delimited run of ``data`` with probability ``rate``."""
        out = bytearray(data)
        start = 0
        while start < len(out):
            stop = out.find(0, start)
            stop = len(out) if stop < 0 else stop
            if stop > start and self._rng.random() < rate:
                out[self._rng.randrange(start, stop)] ^= 1 << self._rng.randrange(8)
            start = stop + 1
        return bytes(out)


class PtyPort:
    """The board's end of a pseudo-terminal in raw mode; the host opens ``url`` (the slave path).

    The emulator keeps the slave open too, so the link survives a host closing
    and reopening it; what it writes while no host reads is dropped once the
    terminal's buffer is full.
    """

    def __init__(self) -> None:
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        os.set_blocking(self._master, False)
        self.url = os.ttyname(self._slave)
        self.dropped_bytes = 0

    def fds(self) -> list[int]:
        return [self._master]

    def receive(self, fd: int) -> bytes:
        try:
            return os.read(self._master, 4096)
        except (BlockingIOError, InterruptedError):
            return b""

    def send(self, data: bytes) -> None:
        if not data:
            return
        try:
            sent = os.write(self._master, data)
        except (BlockingIOError, InterruptedError):
            sent = 0
        self.dropped_bytes += len(data) - sent

    def close(self) -> None:
        for fd in (self._master, self._slave):
            with contextlib.suppress(OSError):
                os.close(fd)


class TcpPort:
    """A TCP server on ``host:port`` for one client at a time; ``url`` is its pyserial URL.

    A second client is refused (closed at once) while one is connected.
    """

    def __init__(self, port: int = 0, host: str = "127.0.0.1") -> None:
        self._listener = socket.create_server((host, port))
        self._listener.setblocking(False)
        self._client: socket.socket | None = None
        bound_host, bound_port = self._listener.getsockname()[:2]
        self.url = f"socket://{bound_host}:{bound_port}"
        self.dropped_bytes = 0
        self.on_connect: Callable[[], None] = lambda: None

    def fds(self) -> list[int]:
        fds = [self._listener.fileno()]
        if self._client is not None:
            fds.append(self._client.fileno())
        return fds

    def receive(self, fd: int) -> bytes:
        if fd == self._listener.fileno():
            self._accept()
            return b""
        if self._client is None:
            return b""
        try:
            data = self._client.recv(4096)
        except (BlockingIOError, InterruptedError):
            return b""
        except OSError:
            data = b""
        if not data:
            self._drop_client()
        return data

    def send(self, data: bytes) -> None:
        if not data:
            return
        sent = 0
        if self._client is not None:
            try:
                sent = self._client.send(data)
            except (BlockingIOError, InterruptedError):
                sent = 0
            except OSError:
                self._drop_client()
        self.dropped_bytes += len(data) - sent

    def close(self) -> None:
        self._drop_client()
        self._listener.close()

    def _accept(self) -> None:
        try:
            client, _ = self._listener.accept()
        except (BlockingIOError, InterruptedError):
            return
        if self._client is not None:
            client.close()
            return
        client.setblocking(False)
        client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._client = client
        self.on_connect()

    def _drop_client(self) -> None:
        if self._client is not None:
            with contextlib.suppress(OSError):
                self._client.close()
            self._client = None


class Emulator:
    """An emulated board serving ``plant`` (real time, on the monotonic clock) on a pty
    (default) or TCP; run with ``serve``."""

    def __init__(self, plant: Backend, *, tcp_port: int | None = None,
                 faults: Faults | None = None, seed: int = 0) -> None:
        self.board = EmulatedBoard(plant, faults=faults, seed=seed, plant_time=True)
        self.port: PtyPort | TcpPort
        if tcp_port is None:
            self.port = PtyPort()
        else:
            self.port = TcpPort(tcp_port)
            self.port.on_connect = self.board.reader.reset
        self.running = False

    @property
    def url(self) -> str:
        """What the host passes to ``serial_for_url``: a pty path or ``socket://HOST:PORT``."""
        return self.port.url

    def serve(self) -> None:
        """Serve until ``stop`` is called (from a signal handler or another thread)."""
        board, port = self.board, self.port
        board.plant.open()
        self.running = True
        try:
            while self.running:
                now = time.monotonic_ns()
                port.send(board.poll(now))
                timeout_s = max(0, board.next_event_ns(now) - time.monotonic_ns()) / 1e9
                for fd in self._wait(timeout_s):
                    data = port.receive(fd)
                    if data:
                        port.send(board.receive(data, time.monotonic_ns()))
        finally:
            board.plant.close()
            port.close()

    def stop(self) -> None:
        self.running = False

    def summary(self) -> dict[str, object]:
        """Counts since start, for the operator and for tests."""
        board = self.board
        return {"url": self.url, "applied": board.applied, "naks": board.naks,
                "rx_errors": board.rx_errors, "held": board.held, "watchdog": board.watchdog,
                "flipped_words": board.flipped, "held_back": board.holds,
                "dropped_bytes": self.port.dropped_bytes, **board.counters.as_dict()}

    def _wait(self, timeout_s: float) -> list[int]:
        if self.board.silent:
            time.sleep(timeout_s)
            return []
        return select.select(self.port.fds(), [], [], timeout_s)[0]
