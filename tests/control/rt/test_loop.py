"""The loop's safety logic, ticked in-process against a scripted backend.

The backend here is a stand-in for iron whose readings the test dictates (it
never moves unless told), so the glitch filter, the supervisor, the row checks
and the fail-safe can be driven exactly; the real subprocess on the real
simulator is exercised in test_client.py and tests/faults.
"""

from __future__ import annotations

import math
import re
import socket
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace

import numpy as np
import pytest

from control.rt import sealed, shm
from control.rt.channel import client_end, controller_end
from control.rt.commands import JogPosition, Manual, Reset, StartMove
from control.rt.events import Notice
from control.rt.law import pi
from control.rt.layout import ESTOP_WORD, ControlLayout, Mode, MoveLayout
from control.rt.loop import Controller, LoopConfig
from control.rt.outbox import OUTBOX_LIMIT
from control.rt.wire import Wire
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
        self.supply_mpa = math.nan
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
def controller_on(machine: Machine) -> Iterator[tuple[Controller, ScriptedBackend, Wire]]:
    backend = ScriptedBackend(machine)
    ours, theirs = socket.socketpair()
    layout = ControlLayout(machine.n_joints)
    segment = shm.create("looptest", layout.size)
    layout.write_header(segment.buf)
    controller = Controller(machine, backend, controller_end(theirs), segment.buf,
                            LoopConfig(period_ns=1_000_000, heartbeat_timeout_ns=10**12))
    controller.start()
    client = client_end(ours)
    try:
        yield controller, backend, client
    finally:
        controller.release()
        shm.release(segment, unlink=True)
        client.close()


@pytest.fixture
def rig() -> Iterator[tuple[Controller, ScriptedBackend, Wire]]:
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


def teleport(controller: Controller, backend: ScriptedBackend, j: int, q: float) -> None:
    """Put joint ``j`` at ``q`` as a reset finds it (believed outright), holding there."""
    backend.positions[j] = q
    controller.encoders.resync(backend, controller.config.period_ns)
    controller.modes.hold_here()
    ticks(controller, backend, 2)


def events(client: Wire) -> list[tuple[str, dict]]:
    """What the controller has sent: it sends in its tick, in this process, so every event is
    in the socket already (waiting 50 ms after the last cost the module 1.2 s)."""
    out = []
    while client.poll(0):
        event = client.recv().record
        out.append((event.KIND, event.payload))
    return out


def test_the_first_status_holds_where_the_joints_are(rig) -> None:
    """``start`` publishes before any tick: the desired it publishes is the hold target,
    where the joints are (it read 0 until the first tick's law, and a jog measured from the
    first status ran 1.5 deg long)."""
    controller, _backend, _client = rig
    assert controller.tick_count == 0 and controller.modes.mode == Mode.HOLD
    assert controller.modes.desired == pytest.approx(HOME, abs=0.1)
    assert controller.modes.desired == controller.modes.hold_target


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


def test_a_glitch_is_rejected_and_counted_and_a_lying_encoder_latches(rig) -> None:
    controller, backend, client = rig
    backend.positions[0] = HOME[0] + 500.0  # In/Out cannot move 500 mm in 1 ms
    ticks(controller, backend, 1)
    assert controller.encoders.position[0] == pytest.approx(HOME[0], abs=0.3)
    assert controller.encoders.glitches[0] == 1 and not controller.guards.latched
    ticks(controller, backend, 4)  # five impossible readings in a row: a stuck bit, not a glitch
    assert controller.encoders.position[0] == pytest.approx(HOME[0], abs=0.3)  # never believed
    assert controller.guards.latched and backend.written == [0.0] * 6
    fault = next(p for name, p in events(client) if name == "fault")
    assert fault["kind"] == "feedback" and fault["joint"] == 0
    assert "In/Out's encoder read 5 jumps in a row" in fault["message"]


def test_a_reset_believes_where_the_joint_now_is(rig) -> None:
    controller, backend, _client = rig
    backend.positions[0] = HOME[0] + 500.0
    ticks(controller, backend, 5)
    assert controller.guards.latched
    controller.channel.deliver(Reset())
    ticks(controller, backend, 2)
    assert not controller.guards.latched, controller.guards.reason
    assert controller.encoders.position[0] == pytest.approx(HOME[0] + 500.0, abs=0.3)


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
    controller.channel.deliver(Manual((40.0,) * 6))
    ticks(controller, backend, 2)
    assert all(backend.written)
    backend.fail_reads = 1
    ticks(controller, backend, 1)
    assert backend.written == [0.0] * 6
    assert controller.guards.latched and "scripted read failure" in controller.guards.reason
    ticks(controller, backend, 3)
    assert backend.written == [0.0] * 6
    assert any(name == "estop" for name, _ in events(client))


def test_a_joint_that_cannot_hold_trips_one_window_after_it_falls_behind(rig) -> None:
    """Zero hold gains: no duty, so no valve opens and the joint stays 80° off its target;
    following error, while holding, closes every valve."""
    controller, backend, client = rig
    zero = pi(UNIMATE, 0.0, 0.0)
    controller.modes.set_coefficients("hold", zero)
    controller.modes.hold_target[3] = 80.0  # Bend told to hold 80° but it sits at 0°
    window_ms = UNIMATE.supervision.window_s * 1e3
    for k in range(1, 400):  # noqa: B007  # k: the tick it tripped on
        ticks(controller, backend, 1)
        if controller.guards.latched:
            break
    assert controller.guards.latched and backend.written == [0.0] * 6
    assert k <= window_ms + 2 * UNIMATE.n_joints, f"tripped after {k} ms"
    faults = [p for name, p in events(client) if name == "fault"]
    assert faults[0]["kind"] == "following_error" and faults[0]["joint"] == 3
    assert "while holding; valves closed" in faults[0]["message"]


def test_a_valve_held_open_with_no_motion_is_a_feedback_fault(rig) -> None:
    """The scripted joint never moves: Rotate at 60 % for a window is a frozen encoder (or a
    seized joint): feedback fault, E-stop latched, within the window and a sample."""
    controller, backend, client = rig
    controller.channel.deliver(Manual((0.0, 60.0, 0.0, 0.0, 0.0, 0.0)))
    for k in range(1, 400):  # noqa: B007  # k: the tick it tripped on
        ticks(controller, backend, 1)
        if controller.guards.latched:
            break
    assert k <= UNIMATE.supervision.window_s * 1e3 + 2 * UNIMATE.n_joints, f"after {k} ms"
    fault = next(p for name, p in events(client) if name == "fault")
    assert fault["kind"] == "feedback" and fault["joint"] == 1
    assert "has not moved" in fault["message"] and backend.written == [0.0] * 6


def test_a_reading_moving_against_its_valve_is_a_feedback_fault(rig) -> None:
    controller, backend, client = rig
    controller.channel.deliver(Manual((0.0, 0.0, 0.0, 0.0, 0.0, 60.0)))
    for _ in range(400):
        backend.positions[5] -= 0.03  # Swivel opens upward and reads 30°/s downward
        ticks(controller, backend, 1)
        if controller.guards.latched:
            break
    fault = next(p for name, p in events(client) if name == "fault")
    assert fault["kind"] == "feedback" and fault["joint"] == 5 and "the other way" in \
        fault["message"]


def test_a_plausible_motion_in_manual_is_not_a_fault(rig) -> None:
    controller, backend, client = rig
    controller.channel.deliver(Manual((0.0, 50.0, 0.0, 0.0, 0.0, 0.0)))
    for _ in range(600):
        backend.positions[1] += 0.02  # 20°/s for 50 % duty: about what the valve gives
        ticks(controller, backend, 1)
    assert not controller.guards.latched, controller.guards.reason
    assert [p for name, p in events(client) if name == "fault"] == []


def test_a_believed_position_outside_the_range_is_a_feedback_fault(rig) -> None:
    controller, backend, client = rig
    teleport(controller, backend, 2, 29.8)
    for _ in range(40):  # Up/Down creeps past its 30° limit by way of plausible readings
        backend.positions[2] += 0.02
        ticks(controller, backend, 1)
    assert controller.guards.latched
    fault = next(p for name, p in events(client) if name == "fault" and p["kind"] == "feedback")
    assert fault["joint"] == 2 and "outside its range" in fault["message"]


def test_the_client_estop_word_latches_on_the_next_tick(rig) -> None:
    controller, backend, _client = rig
    controller.channel.deliver(Manual((30.0,) * 6))
    ticks(controller, backend, 2)
    controller.client.words[ESTOP_WORD] += 1
    ticks(controller, backend, 1)
    assert controller.guards.latched and backend.written == [0.0] * 6
    assert controller.guards.reason == "operator E-stop"


def test_stop_at_limits_in_manual(rig) -> None:
    controller, backend, client = rig
    teleport(controller, backend, 2, 29.99)  # Up/Down one count below its 30° limit
    controller.channel.deliver(Manual((0.0, 0.0, 50.0, 0.0, 0.0, -50.0)))
    ticks(controller, backend, 2)
    assert controller.modes.duty[2] == 0.0 and controller.modes.duty[5] == -50.0
    (limit,) = [p for name, p in events(client) if name == "fault"]
    assert limit["kind"] == "limit" and limit["joint"] == 2


def test_a_joint_past_its_limit_in_hold_gets_no_duty_toward_it(rig) -> None:
    controller, backend, client = rig
    controller.modes.set_coefficients("hold", pi(UNIMATE, -30.0, 0.0))  # pushes the wrong way
    teleport(controller, backend, 2, 29.9)
    backend.positions[2] = 30.1  # past the 30° limit, by a plausible step
    ticks(controller, backend, 8)
    assert controller.modes.duty[2] == 0.0
    limit = next(p for name, p in events(client) if name == "fault" and p["kind"] == "limit")
    assert limit["joint"] == 2 and "is past its limit" in limit["message"]


def start_move(controller: Controller, path: list[list[float]], kind: str,
               settle_rows: int = 300, tracking: bool = False) -> Iterator[None]:
    layout = MoveLayout(len(path), UNIMATE.n_joints, settle_rows=settle_rows)
    segment = shm.create("loopmove", layout.size)
    layout.write_header(segment.buf)
    controller.channel.deliver(StartMove(1, segment.name, kind, tracking, len(path)),
                               (sealed.seal(np.array(path)),))
    return segment


@pytest.mark.parametrize(("kind", "row", "message"), [
    ("path", [HOME[0], 5.0, *HOME[2:]], "jumps +5"),
    ("step", [HOME[0], 200.0, *HOME[2:]], "outside -110…110"),
    ("step", [HOME[0], float("nan"), *HOME[2:]], "nan"),
])
def test_a_row_that_cannot_be_trusted_aborts_the_move_and_holds(rig, kind: str, row: list,
                                                                 message: str) -> None:
    controller, backend, client = rig
    segment = start_move(controller, [HOME, HOME, row, HOME], kind)
    try:
        ticks(controller, backend, 4)
        assert controller.modes.move is None and controller.modes.mode == Mode.HOLD
        done = next(p for name, p in events(client) if name == "move_done")
        assert done["status"].startswith("fault: move 1 row 2: Rotate") and message in \
            done["status"], done
        assert controller.modes.hold_target[1] == pytest.approx(0.0, abs=0.1)
    finally:
        shm.release(segment, unlink=True)


def test_a_step_kind_may_jump(rig) -> None:
    controller, backend, client = rig
    segment = start_move(controller, [HOME, [HOME[0], 5.0, *HOME[2:]], [HOME[0], 5.0,
                                                                        *HOME[2:]]], "step")
    try:
        ticks(controller, backend, 3)
        teleport(controller, backend, 1, 5.0)  # the scripted arm is there: in position
        ticks(controller, backend, 250)
        done = next(p for name, p in events(client) if name == "move_done")
        assert done["status"] == "complete", done
    finally:
        shm.release(segment, unlink=True)


def settle_path(target: float) -> list[list[float]]:
    """A step of Rotate to ``target``, three rows."""
    return [HOME, [HOME[0], target, *HOME[2:]], [HOME[0], target, *HOME[2:]]]


def test_a_move_settles_at_its_end_before_it_is_complete(rig) -> None:
    """Issue 24: after its path's last row the move holds the end and stays the move,
    SETTLING, recording rows, until every joint has been within its goal tolerance and
    slower than its stopped speed for 100 ms; each joint's settle time goes into MoveDone."""
    controller, backend, client = rig
    segment = start_move(controller, settle_path(0.3), "step", settle_rows=1000)
    try:
        ticks(controller, backend, 3)  # the path: the arm, at 0, is 0.3° off, inside 0.5
        layout = controller.modes.move.layout
        settling = []
        for _ in range(400):
            ticks(controller, backend, 1)
            move = controller.modes.move
            if move is None:
                break
            settling.append(controller.modes.settling)
        assert all(settling) and 200 <= len(settling) <= 215, len(settling)
        assert controller.modes.hold_target[1] == 0.3 and controller.modes.mode == Mode.HOLD
        done = next(p for name, p in events(client) if name == "move_done")
        assert done["status"] == "complete", done
        settle = done["settle"]
        assert settle["settle_s"][1] == pytest.approx(0.1, abs=0.005)  # the speed window filled
        assert settle["goal_error"][1] == pytest.approx(-0.3, abs=0.03)
        assert settle["path_end_s"] == pytest.approx(0.003, abs=0.0015)
        assert layout.recorded(segment.buf) == done["recorded"] > 200  # the settle's rows too
    finally:
        shm.release(segment, unlink=True)


def test_a_move_not_in_position_by_goal_time_ends_unsettled_naming_the_joint_and_holds(
        rig) -> None:
    controller, backend, client = rig
    controller.modes.set_coefficients("hold", pi(UNIMATE, 0.0, 0.0))  # hold gains zeroed
    segment = start_move(controller, settle_path(2.0), "step", settle_rows=10)
    try:
        ticks(controller, backend, 3)  # the scripted arm never moves: 2° off, inside 2.5° FERROR
        flags = []
        while controller.modes.move is not None and len(flags) < 3000:
            ticks(controller, backend, 1)
            flags.append(controller.modes.settling)
        done = next(p for name, p in events(client) if name == "move_done")
        assert re.fullmatch(r"unsettled: Rotate (1\.99|2\.00)° from its goal after 2 s",
                            done["status"]), done["status"]
        assert 1990 <= len(flags) <= 2010 and all(flags[:-1])
        assert done["settle"]["settle_s"][1] is None and done["settle"]["settle_s"][0] > 0
        assert done["recorded"] == 3 + 10  # the segment's room, no more
        assert controller.modes.mode == Mode.HOLD and controller.modes.hold_target[1] == 2.0
    finally:
        shm.release(segment, unlink=True)


def test_an_open_loop_move_has_no_goal(rig) -> None:
    controller, backend, client = rig
    segment = start_move(controller, [[0.0] * 6] * 3, "tracking_actuate", settle_rows=0,
                         tracking=True)
    try:
        ticks(controller, backend, 4)
        done = next(p for name, p in events(client) if name == "move_done")
        assert done["status"] == "complete" and done["settle"] == {}, done
    finally:
        shm.release(segment, unlink=True)


def test_a_second_with_over_a_fifth_of_its_ticks_overrun_aborts_the_move_and_holds(rig) -> None:
    controller, backend, client = rig
    controller.modes.set_coefficients("track", pi(UNIMATE, 1.0, 0.0))  # no integrator to wind
    segment = start_move(controller, [HOME] * 3000, "path")  # up on a joint that never moves
    try:
        ticks(controller, backend, 1100)
        for k in range(1000):  # a flooded link: three ticks in ten end past their deadline
            ticks(controller, backend, 1)
            deadline = controller.deadline
            controller.latency.next_deadline(deadline, deadline + (1_500_000 if k % 10 < 3
                                                                   else 100_000))
        fault = next(p for name, p in events(client) if name == "fault")
        assert fault["kind"] == "overrun" and "% of the last second's ticks" in fault["message"]
        assert controller.modes.move is None and controller.modes.mode == Mode.HOLD
        assert not controller.guards.latched
    finally:
        shm.release(segment, unlink=True)


def overload(controller: Controller, backend: ScriptedBackend, drift_mm: float) -> None:
    """A flooded link for a second, In/Out drifting ``drift_mm`` meanwhile, unopposed."""
    for k in range(1000):  # three ticks in ten end past their deadline
        backend.positions[0] += drift_mm / 1000
        ticks(controller, backend, 1)
        deadline = controller.deadline
        controller.latency.next_deadline(deadline, deadline + (1_500_000 if k % 10 < 3
                                                               else 100_000))


@pytest.mark.parametrize("moving", [False, True], ids=["holding", "in a move"])
def test_an_overrun_hold_keeps_the_commanded_position_not_where_the_arm_drifted(
        rig, moving: bool) -> None:
    """Issue 24 item 4: a stall is the controller's fault, not the arm's: the hold after it is
    where the arm was commanded to be (the hold target, the move's desired), so starvation
    never moves the target, however often it holds."""
    controller, backend, client = rig
    for which in ("hold", "track"):
        controller.modes.set_coefficients(which, pi(UNIMATE, 0.0, 0.0))  # nothing opposes it
    segment = start_move(controller, [HOME] * 5000, "path") if moving else None
    try:
        for _ in range(3):
            overload(controller, backend, 1.0)
            fault = next(p for name, p in events(client) if name == "fault")
            assert fault["kind"] == "overrun" and "holding the commanded" in fault["message"]
            assert controller.modes.move is None and controller.modes.mode == Mode.HOLD
            assert controller.modes.position[0] > HOME[0] + 0.5  # it drifted
            assert controller.modes.hold_target[0] == pytest.approx(HOME[0], abs=0.27)
    finally:
        if segment is not None:
            shm.release(segment, unlink=True)


def test_one_long_stall_is_not_an_overload(rig) -> None:
    controller, backend, client = rig
    controller.modes.set_coefficients("track", pi(UNIMATE, 1.0, 0.0))
    segment = start_move(controller, [HOME] * 3000, "path")
    try:
        for k in range(2100):
            ticks(controller, backend, 1)
            deadline = controller.deadline
            controller.latency.next_deadline(deadline, deadline + (900_000_000 if k == 1500
                                                                   else 100_000))
        assert controller.modes.move is not None
        assert [p for name, p in events(client) if name == "fault"] == []
    finally:
        shm.release(segment, unlink=True)


def test_a_stall_in_a_move_is_listed_and_said(rig) -> None:
    controller, backend, client = rig
    segment = start_move(controller, [HOME] * 5, "path")
    try:
        ticks(controller, backend, 2)
        backend.clock.sleep_until(backend.clock.now_ns() + 300_000_000)  # a 0.3 s stall
        ticks(controller, backend, 250)  # the path's rows, then its settle
        done = next(p for name, p in events(client) if name == "move_done")
        assert done["status"] == "complete, with a 0.3 s controller stall", done
        ((at, length),) = done["gaps"]
        assert length == pytest.approx(0.301, abs=0.002)
        assert at == pytest.approx(0.002)  # after its second row
    finally:
        shm.release(segment, unlink=True)


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
    controller.channel.deliver(command)
    ticks(controller, backend, 3)
    (refused,) = [p for name, p in events(client) if name == "refused"]
    assert refused["reason"], refused
    assert not controller.guards.latched, controller.guards.reason
    assert controller.modes.mode == Mode.HOLD
    assert controller.modes.hold_target == before
