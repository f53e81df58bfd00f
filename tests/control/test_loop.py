"""The loop's safety logic, ticked in-process against a scripted backend.

The backend here is a stand-in for iron whose readings the test dictates, so
the glitch filter, fail-safe and following-error rules can be driven exactly;
the real subprocess on the real simulator is exercised in test_client.py.
"""

from __future__ import annotations

import socket
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from multiprocessing.connection import Connection

import pytest

from control import shm
from control.commands import JogPosition, Manual
from control.events import Notice
from control.layout import ControlLayout, Mode
from control.loop import Controller, LoopConfig
from control.outbox import OUTBOX_LIMIT
from hw.backend import LinkCounters, StepClock
from hw.gray import binary_to_gray
from hw.machine import Machine, load_machine
from hw.transmission import Transmission

UNIMATE = load_machine("unimate2000b")
HOME = [1500.0, 0.0, 0.0, 0.0, 0.0, 0.0]


class ScriptedBackend:
    """Reports the positions the test sets (as Gray words), records what is written."""

    def __init__(self, machine: Machine) -> None:
        self.machine = machine
        self.transmission = Transmission(machine)
        self.clock = StepClock()
        self.counters = LinkCounters()
        self.estop = False
        self.fault = ""
        self.positions = list(HOME)
        self.written: list[float] = []
        self.fail_reads = 0

    @property
    def sample_ns(self) -> int:
        return self.clock.now_ns()

    def word(self, j: int) -> int:
        actuator = [0.0] * self.machine.n_joints
        self.transmission.actuators_from_joints(self.positions, actuator)
        return binary_to_gray(round(self.transmission.count_of(j, actuator[j])))

    def open(self) -> None: ...

    def close(self) -> None: ...

    def reconnect(self) -> None: ...

    def read(self, raw: list[int]) -> None:
        if self.fail_reads:
            self.fail_reads -= 1
            raise RuntimeError("scripted read failure")
        raw[:] = [self.word(j) for j in range(self.machine.n_joints)]

    def write(self, duty: list[float]) -> None:
        self.written = list(duty)


@contextmanager
def controller_on(machine: Machine) -> Iterator[tuple[Controller, ScriptedBackend, Connection]]:
    backend = ScriptedBackend(machine)
    ours, theirs = socket.socketpair()
    layout = ControlLayout(machine.n_joints)
    segment = shm.create("looptest", layout.size)
    layout.write_header(segment.buf)
    controller = Controller(machine, backend, Connection(theirs.detach()), segment.buf,
                            LoopConfig(period_ns=1_000_000, heartbeat_timeout_ns=10**12))
    controller.start()
    client = Connection(ours.detach())
    try:
        yield controller, backend, client
    finally:
        controller.release()
        shm.release(segment, unlink=True)
        client.close()


@pytest.fixture
def rig() -> Iterator[tuple[Controller, ScriptedBackend, Connection]]:
    with controller_on(UNIMATE) as parts:
        yield parts


def ticks(controller: Controller, backend: ScriptedBackend, n: int) -> None:
    for _ in range(n):
        backend.clock.sleep_until(backend.clock.now_ns() + 1_000_000)
        controller.deadline = backend.clock.now_ns()
        try:
            controller.tick(backend.clock.now_ns())
        except Exception as exc:
            controller.fail_safe(exc)


def events(client: Connection) -> list[tuple[str, dict]]:
    out = []
    while client.poll(0.05):
        event = client.recv()
        out.append((event.KIND, event.payload))
    return out


def test_events_never_block_a_client_that_stopped_reading(rig) -> None:
    controller, backend, _client = rig
    started = time.monotonic()
    for i in range(20_000):
        controller.outbox.put(Notice(f"flood {i} " + "x" * 200))
        controller.outbox.flush()
    assert time.monotonic() - started < 30, "flushing waited on the reader"
    assert len(controller.outbox.queue) <= OUTBOX_LIMIT
    ticks(controller, backend, 5)
    assert controller.tick_count >= 5


def test_a_glitch_is_rejected_and_counted_then_a_real_jump_is_believed(rig) -> None:
    controller, backend, _client = rig
    backend.positions[0] = HOME[0] + 500.0  # In/Out cannot move 500 mm in 1 ms
    ticks(controller, backend, 1)
    assert controller.encoders.position[0] == pytest.approx(HOME[0], abs=0.3)
    assert controller.encoders.glitches[0] == 1
    ticks(controller, backend, 5)  # still there after the resync count: it is real
    assert controller.encoders.position[0] == pytest.approx(HOME[0] + 500.0, abs=0.3)
    assert controller.encoders.glitches[0] == 5


def test_a_word_wider_than_the_encoder_is_decoded_and_judged_not_a_crash(rig) -> None:
    """A garbled 32-bit word (a high bit set past the encoder's 13) decodes outside the
    lookup table and is rejected by the glitch filter as an impossible jump."""
    controller, backend, _client = rig
    good = backend.word
    backend.word = lambda j: good(j) | (1 << 20) if j == 1 else good(j)
    ticks(controller, backend, 1)
    assert not controller.guards.latched, controller.guards.reason
    assert controller.encoders.glitches[1] == 1
    assert controller.encoders.position[1] == pytest.approx(HOME[1], abs=0.1)


def test_a_gray_encoder_too_wide_for_the_table_is_decoded_word_by_word() -> None:
    wide = replace(UNIMATE, encoder_bits=24)
    with controller_on(wide) as (controller, backend, _client):
        ticks(controller, backend, 3)
        assert controller.encoders.position == pytest.approx(HOME, abs=0.3)
        assert controller.encoders.glitches == [0] * 6


def test_a_plausible_move_is_never_a_glitch(rig) -> None:
    controller, backend, _client = rig
    for _ in range(100):
        backend.positions[1] += 0.05  # 50°/s, inside Rotate's 60°/s
        ticks(controller, backend, 1)
    assert controller.encoders.glitches[1] == 0
    assert controller.encoders.position[1] == pytest.approx(backend.positions[1], abs=0.05)


def test_an_exception_in_a_tick_closes_the_valves_and_latches(rig) -> None:
    controller, backend, client = rig
    controller.handle(Manual((40.0,) * 6))
    ticks(controller, backend, 2)
    assert all(backend.written)
    backend.fail_reads = 1
    ticks(controller, backend, 1)
    assert backend.written == [0.0] * 6
    assert controller.guards.latched and "scripted read failure" in controller.guards.reason
    ticks(controller, backend, 3)
    assert backend.written == [0.0] * 6
    assert any(name == "estop" for name, _ in events(client))


def test_following_error_while_holding_closes_the_valves(rig) -> None:
    controller, backend, client = rig
    controller.modes.hold_target[3] = 80.0  # Bend told to hold 80° but it sits at 0° and won't move
    ticks(controller, backend, 600)
    assert controller.guards.latched and backend.written == [0.0] * 6
    faults = [p for name, p in events(client) if name == "fault"]
    assert faults[0]["kind"] == "following_error" and faults[0]["joint"] == 3
    assert "while holding; valves closed" in faults[0]["message"]
    assert controller.modes.mode == Mode.HOLD


def test_stop_at_limits_in_manual(rig) -> None:
    controller, backend, client = rig
    backend.positions[2] = 29.99  # Up/Down one count below its 30° limit
    ticks(controller, backend, 6)
    controller.handle(Manual((0.0, 0.0, 50.0, 0.0, 0.0, -50.0)))
    ticks(controller, backend, 2)
    assert controller.modes.duty[2] == 0.0 and controller.modes.duty[5] == -50.0
    (limit,) = [p for name, p in events(client) if name == "fault"]
    assert limit["kind"] == "limit" and limit["joint"] == 2


def _bypassing_checks(cls: type, **fields: object) -> object:
    """A record built as unpickling builds it: no ``__init__``, so no checks ran."""
    record = object.__new__(cls)
    for name, value in fields.items():
        object.__setattr__(record, name, value)
    return record


@pytest.mark.parametrize("command", [
    _bypassing_checks(JogPosition, joint=6, delta=1.0),
    _bypassing_checks(JogPosition, joint=-1, delta=10.0),
    _bypassing_checks(JogPosition, joint=1, delta=float("nan")),
    _bypassing_checks(Manual, duty=(40.0,) * 5),
    _bypassing_checks(Manual, duty=(float("inf"),) * 6),
    ("jog_position", -1, 10.0),
    "estop",
], ids=["joint 6", "joint -1", "nan step", "five duties", "inf duty", "a tuple", "a string"])
def test_a_command_that_fails_its_checks_on_arrival_is_refused_and_moves_nothing(
        rig, command: object) -> None:
    controller, backend, client = rig
    before = list(controller.modes.hold_target)
    controller.handle(command)
    ticks(controller, backend, 3)
    (refused,) = [p for name, p in events(client) if name == "refused"]
    assert refused["reason"], refused
    assert not controller.guards.latched, controller.guards.reason
    assert controller.modes.mode == Mode.HOLD
    assert controller.modes.hold_target == before
