"""The real-hardware backend: an I/O board on a serial link (docs/protocol.md).

Tick scheme (protocol section 4): every ``write`` sends one DUTY frame, which
is also the board's proof of life; the board applies it, latches the encoders
and answers with one REPORT. ``read`` drains the link and returns the newest
REPORT's words, so the control loop's reading at tick k+1 is the board's
answer to the command of tick k: one tick of latency, by design. If that
answer is not in yet, ``read`` waits for it at most ``reply_wait_s``, then
uses the previous one (counted in ``late_replies``) and leaves ``sample_ns``
as it was: the same words, the same sample. A ``read`` with nothing sent since
the last one (a resync reading the joints before the loop writes) asks for a
new sample with a HEARTBEAT, so that it does not re-read the same words.

Faults never raise out of ``read`` or ``write``; they set ``fault`` (the
control loop then stops motion) and count in ``counters``. A lost link (the
port vanished, or no valid frame for ``watchdog_s``) closes the port and keeps
the last readings; ``reconnect`` is the operator's way back. A board watchdog
trip is a fault too: the valves were closed behind the controller's back.
"""

from __future__ import annotations

import contextlib
import itertools
import math
import os
import select
import time
from collections.abc import Sequence

import serial

from hw.backend import LinkCounters, RealClock
from hw.machine import Machine
from hw.serial.messages import (
    BOARD_TO_HOST,
    DUTY_MAX,
    DUTY_SCALE,
    BoardConfig,
    Config,
    ConfigAck,
    Duty,
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

READ_CHUNK = 4096
MAX_READS = 64
RESEND_S = 0.1
RECONNECT_S = 1.0  # how long a reconnect keeps trying, with back-off, before it says why not
RECONNECT_FIRST_WAIT_S = 0.02


class BoardError(ConnectionError):
    """The I/O board could not be reached or refused the configuration."""


class BoardClock:
    """The board's latch time (``Report.t_us``, a wrapping u32) on the host's monotonic clock.

    A reply's arrival is not when its words were latched: a host or board that was
    descheduled delivers old words late, and timing them by arrival makes real motion
    look faster than the joint can move (a false encoder glitch). The board's own time
    is exact between samples; it is placed on the host clock by the smallest arrival
    delay seen so far (the usual one-way clock estimate), so it never runs ahead of the
    host's clock.
    """

    def __init__(self) -> None:
        self._last_us: int | None = None
        self._board_us = 0  # unwrapped
        self._offset_ns: int | None = None

    def host_ns(self, t_us: int, arrived_ns: int) -> int:
        """The host time at which the board latched a report stamped ``t_us``."""
        if self._last_us is not None:  # signed 32-bit step: wraps forward, never 71 min back
            self._board_us += ((t_us - self._last_us + 2**31) & 0xFFFF_FFFF) - 2**31
        self._last_us = t_us
        board_ns = self._board_us * 1000
        delay = arrived_ns - board_ns
        if self._offset_ns is None or delay < self._offset_ns:
            self._offset_ns = delay
        return board_ns + self._offset_ns


class SerialBackend:
    """``hw.backend.Backend`` over pyserial to an I/O board (or the emulator).

    ``url`` is anything ``serial.serial_for_url`` opens with a file descriptor:
    ``/dev/ttyACM0``, a pty path, ``socket://127.0.0.1:PORT``. ``watchdog_s``
    is both the board's valve watchdog and the host's link timeout;
    ``heartbeat_s`` is how often a quiet board reports anyway;
    ``open_timeout_s`` bounds the wait for the board's answers in ``open``;
    ``reply_wait_s`` is how long ``read`` waits for a late answer;
    ``baudrate`` matters only on a real UART.
    """

    def __init__(self, machine: Machine, url: str, *, watchdog_s: float = 0.05,
                 heartbeat_s: float = 0.02, open_timeout_s: float = 0.5,
                 reply_wait_s: float = 0.0002, baudrate: int = 1_000_000) -> None:
        self.machine = machine
        self.url = url
        self.clock = RealClock()
        self.counters = LinkCounters()
        self.board_config = BoardConfig.from_machine(machine, watchdog_s, heartbeat_s)
        self.watchdog_s = watchdog_s
        self.open_timeout_s = open_timeout_s
        self.reply_wait_s = reply_wait_s
        self.baudrate = baudrate
        self.firmware = 0
        self.last_report: Report | None = None
        self.last_status: Status | None = None
        self.late_replies = 0
        self.rtt_ns = 0
        n = machine.n_joints
        self._n = n
        self._words: Sequence[int] = (0,) * n
        self.sample_ns = 0  # when the board latched the newest words, on the host clock
        self.supply_mpa = math.nan  # the board has no pressure input
        self._board_clock = BoardClock()
        self._units = [0] * n
        self._port: serial.SerialBase | None = None
        self._reader = MessageReader(self.counters, BOARD_TO_HOST, resync=(MsgType.CONFIG_ACK,))
        self._writer = MessageWriter()
        self._flags = 0
        self._fault = ""
        self._fresh = True
        self._awaiting = False
        self._sent_since_read = False  # a frame went out since the last read: its answer is due
        self._sent_ns = 0
        self._last_rx_ns = 0
        self._watchdog_ns = round(watchdog_s * 1e9)
        # quadrature counters arrive modulo 2**bits and are read back as signed counts
        self._count_bits = machine.encoder_bits if machine.encoder_kind == "quadrature" else 0
        self._reply_wait_ns = round(reply_wait_s * 1e9)

    # -- lifecycle ----------------------------------------------------------------------

    def open(self) -> None:
        """Connect, configure the board and take a first reading; the valves stay closed.

        Raises ``BoardError`` saying what to check when the port cannot be
        opened, the board does not answer within ``open_timeout_s`` or refuses
        the configuration.
        """
        self._disconnect()
        self._connect()
        try:
            ack = self._request(Config(self.board_config))
            assert isinstance(ack, ConfigAck)
            if ack.config != self.board_config:
                raise BoardError(f"the I/O board on {self.url} applied {ack.config}, "
                                 f"not the requested {self.board_config}")
            self.firmware = ack.firmware
            report = self._request(Heartbeat())
            assert isinstance(report, Report)
            self._last_rx_ns = time.monotonic_ns()
            self._on_report(report, self._last_rx_ns)
            if self._fault:
                raise BoardError(f"the I/O board on {self.url}: {self._fault}")
        except BaseException:
            self._disconnect()
            raise

    def close(self) -> None:
        """Command every valve closed and release the port; safe to call twice."""
        if self._port is not None:
            self._send(Duty((0,) * self._n))
        self._disconnect()

    def reconnect(self) -> None:
        """The operator's way back from a lost link or a watchdog trip: reopen from scratch,
        retrying with back-off (20, 40, 80 … ms) for up to ``RECONNECT_S``: a board serving
        one TCP client may not yet have noticed that the old link closed, and resets the
        new one.

        On failure the fault says why, after how many attempts, and the ``BoardError``
        propagates.
        """
        self.close()
        deadline = time.monotonic() + RECONNECT_S
        wait = RECONNECT_FIRST_WAIT_S
        for attempt in itertools.count(1):
            try:
                self.open()
                return
            except BoardError as exc:
                if time.monotonic() + wait >= deadline:
                    self._fault = (f"link lost: reconnect failed after {attempt} attempts in "
                                   f"{RECONNECT_S:g} s: {exc}")
                    raise BoardError(self._fault) from exc
            time.sleep(wait)
            wait *= 2

    # -- the tick -----------------------------------------------------------------------------

    def read(self, raw: list[int]) -> None:
        """Fill ``raw`` with the newest reported encoder words (kept while the link is lost);
        ``sample_ns`` says when they were latched, and changes only with a new REPORT."""
        if self._port is not None:
            if not self._awaiting and not self._sent_since_read:
                self._send(Heartbeat())  # nothing asked since the last read: ask for a sample
            self._sent_since_read = False
            self._service(self._reply_wait_ns if self._awaiting else 0)
            if self._awaiting:
                self.late_replies += 1
        raw[:] = self._words

    def write(self, duty_pct: Sequence[float]) -> None:
        """Send signed duty per joint (percent, clamped to ±100, NaN as 0) as one DUTY frame."""
        if self._port is None:
            return
        units = self._units
        for j in range(self._n):
            units[j] = _to_units(duty_pct[j])
        self._send(Duty(tuple(units), self._should_clear(units)))

    def wait_reply(self, timeout_s: float) -> bool:
        """Wait until the board answered the last frame sent; False on timeout or a lost link."""
        self._service(round(timeout_s * 1e9))
        return self._port is not None and not self._awaiting

    @property
    def estop(self) -> bool:
        return bool(self._flags & Flag.ESTOP)

    @property
    def fault(self) -> str:
        return self._fault

    @property
    def board_flags(self) -> Flag:
        """The board's status flags as last reported."""
        return Flag(self._flags)

    # -- connecting -----------------------------------------------------------------------------

    def _connect(self) -> None:
        try:
            port = serial.serial_for_url(self.url, baudrate=self.baudrate, timeout=0)
        except (OSError, serial.SerialException, ValueError) as exc:
            raise BoardError(f"cannot open {self.url}: {exc}: check the port name "
                             "(a device, a pty path or socket://HOST:PORT) and its permissions "
                             "(dialout group)") from None
        port.reset_input_buffer()
        self._port = port
        self._reader.reset()
        self._fault = ""
        self._flags = 0
        self._fresh = True
        self._awaiting = False
        self._last_rx_ns = time.monotonic_ns()
        self._board_clock = BoardClock()  # a (re)configured board may have restarted its clock

    def _disconnect(self) -> None:
        port, self._port = self._port, None
        self._awaiting = False
        if port is None:
            return
        with contextlib.suppress(OSError, serial.SerialException):
            sock = getattr(port, "_socket", None)
            if sock is None:
                port.close()
                return
            sock.close()  # pyserial's socket:// close() sleeps 0.3 s; the control loop can't
            port._socket = None
            port.is_open = False

    def _request(self, message: Config | Heartbeat) -> ConfigAck | Report:
        """Send ``message`` until the board answers it, resending every ``RESEND_S``."""
        answer_type = ConfigAck if isinstance(message, Config) else Report
        deadline = time.monotonic() + self.open_timeout_s
        while (left := deadline - time.monotonic()) > 0:
            self._send(message)
            seq = self._writer.seq
            resend_at = time.monotonic() + min(left, RESEND_S)
            while (remaining := resend_at - time.monotonic()) > 0:
                for answer in self._receive(remaining):
                    if isinstance(answer, answer_type) and answer.echo_seq == seq:
                        return answer
                    if isinstance(answer, Nak) and answer.echo_seq == seq:
                        raise BoardError(f"the I/O board on {self.url} refused "
                                         f"{_describe(message)}: {_reason_name(answer.reason)}")
        raise BoardError(f"no I/O board answered on {self.url} within {self.open_timeout_s:g} s: "
                         "check the port and that the board is powered")

    def _receive(self, timeout_s: float) -> list[Message | Malformed]:
        """Messages that arrive within ``timeout_s`` (returns at the first batch); for ``open``."""
        port = self._port
        if port is None:
            raise BoardError(f"lost {self.url} while connecting: {self._fault}")
        try:
            if not select.select([port.fileno()], [], [], max(0.0, timeout_s))[0]:
                return []
            data = port.read(READ_CHUNK)
        except (OSError, serial.SerialException) as exc:
            raise BoardError(f"lost {self.url} while connecting: {exc}") from None
        return [message for _, message in self._reader.feed(data)]

    # -- the link at run time ----------------------------------------------------------------------

    def _send(self, message: Message) -> None:
        """One frame, written without blocking straight to the port's descriptor.

        pyserial 3.5's timed ``write`` can report a timeout for a write that
        completed if the process was preempted meanwhile, and its untimed one
        can block the control loop; a frame that does not fit at once means
        the board has stopped reading.
        """
        port = self._port
        if port is None:
            return
        frame = self._writer.encode(message)
        try:
            sent = os.write(port.fileno(), frame)
        except BlockingIOError:
            sent = 0
        except (OSError, serial.SerialException) as exc:
            self._lose(f"{self.url}: write failed: {exc}")
            return
        if sent < len(frame):
            self._lose(f"the I/O board on {self.url} stopped reading (its input is full)")
            return
        self.counters.frames_tx += 1
        self._awaiting = True
        self._sent_since_read = True
        self._sent_ns = time.monotonic_ns()

    def _service(self, wait_ns: int) -> None:
        """Take in what the board sent; wait up to ``wait_ns`` for the answer still pending."""
        port = self._port
        if port is None:
            return
        deadline = time.monotonic_ns() + wait_ns
        try:
            for _ in range(MAX_READS):  # bounded, even if a broken device streams without end
                data = port.read(READ_CHUNK)
                if data:
                    self._take(data)
                    continue
                remaining = deadline - time.monotonic_ns()
                if not self._awaiting or remaining <= 0:
                    break
                select.select([port.fileno()], [], [], remaining / 1e9)
        except (OSError, serial.SerialException) as exc:
            self._lose(f"{self.url}: {exc}")
            return
        silent_ns = time.monotonic_ns() - self._last_rx_ns
        if silent_ns > self._watchdog_ns:
            self._lose(f"no frame from the I/O board for {silent_ns / 1e6:.0f} ms "
                       f"(watchdog {self.watchdog_s * 1e3:g} ms)")

    def _take(self, data: bytes) -> None:
        now = time.monotonic_ns()
        for _, message in self._reader.feed(data):
            if isinstance(message, Malformed):
                continue
            self._last_rx_ns = now
            if isinstance(message, Report):
                self._on_report(message, now)
            elif isinstance(message, Status):
                self.last_status = message
                self._on_flags(message.flags)
            elif isinstance(message, Nak):
                self._set_fault(f"the I/O board refused frame {message.echo_seq} "
                                f"({_type_name(message.rejected_type)}): "
                                f"{_reason_name(message.reason)}"
                                + ("; it has restarted: reconnect"
                                   if message.reason == NakReason.NOT_CONFIGURED else ""))

    def _on_report(self, report: Report, now: int) -> None:
        if len(report.words) != self._n:
            self._set_fault(f"the I/O board reports {len(report.words)} joints, machine "
                            f"{self.machine.name} has {self._n}: check its configuration")
            return
        self.last_report = report
        bits = self._count_bits
        self._words = report.words if not bits else tuple(_signed(w, bits) for w in report.words)
        self.sample_ns = self._board_clock.host_ns(report.t_us, now)
        if not report.flags & Flag.UNSOLICITED and report.echo_seq == self._writer.seq:
            self._awaiting = False
            self.rtt_ns = now - self._sent_ns
        self._on_flags(report.flags)

    def _on_flags(self, flags: int) -> None:
        tripped = flags & Flag.WATCHDOG and not self._flags & Flag.WATCHDOG
        self._flags = flags
        if flags & Flag.ESTOP or not flags & Flag.HELD:
            self._fresh = False
        if tripped:
            self.counters.watchdog_trips += 1
            self._set_fault(f"the I/O board's watchdog closed the valves: no valid command "
                            f"reached it for {self.watchdog_s * 1e3:g} ms; reconnect to resume")

    def _should_clear(self, units: list[int]) -> bool:
        """Ask the board to leave its held state? (protocol section 5.3)

        Only while healthy and the board is held without its E-stop pressed:
        right after ``open`` with any duty, otherwise (after an E-stop was
        released) only with every valve commanded closed.
        """
        flags = self._flags
        if self._fault or not flags & Flag.HELD or flags & Flag.ESTOP:
            return False
        return self._fresh or not any(units)

    def _lose(self, reason: str) -> None:
        self.counters.link_lost += 1
        self._set_fault(f"link lost: {reason}")
        self._disconnect()

    def _set_fault(self, reason: str) -> None:
        if not self._fault:
            self._fault = reason


def _to_units(duty_pct: float) -> int:
    """Percent duty to 0.01 % units, clamped to ±100 %; NaN closes the valve."""
    if -100.0 <= duty_pct <= 100.0:
        return round(duty_pct * DUTY_SCALE)
    if math.isnan(duty_pct):
        return 0
    return DUTY_MAX if duty_pct > 0 else -DUTY_MAX


def _signed(word: int, bits: int) -> int:
    """Read a ``bits``-bit two's complement counter as a signed count."""
    return word - (1 << bits) if word & (1 << (bits - 1)) else word


def _describe(message: Config | Heartbeat) -> str:
    if isinstance(message, Config):
        c = message.config
        return (f"the configuration ({c.n_joints} joints, {c.encoder_bits}-bit encoders, "
                f"watchdog {c.watchdog_ms} ms, heartbeat {c.heartbeat_ms} ms)")
    return "a heartbeat"


def _type_name(code: int) -> str:
    return MsgType(code).name if code in MsgType._value2member_map_ else f"type 0x{code:02X}"


def _reason_name(code: int) -> str:
    return NakReason(code).name if code in NakReason._value2member_map_ else f"reason {code}"
