"""The warm-up shadow (control/rt/warmup.py): the live tick is bit for bit the same with it,
and the shadow never touches the live controller's backend, shared memory or channel.

In-process controllers on the real simulator in lockstep, real shared memory and a real
socketpair for the channel; the commands go through the client's end of it and the
E-stop through the client's word, as a client's do.
"""

from __future__ import annotations

import socket
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from multiprocessing.shared_memory import SharedMemory

import numpy as np
import pytest

from control.rt import sealed, shm
from control.rt.channel import client_end, controller_end
from control.rt.commands import (
    Hold,
    JogPosition,
    JogVelocity,
    Manual,
    Reset,
    SetSpeedMode,
    StartMove,
)
from control.rt.events import Notice
from control.rt.layout import ESTOP_WORD, ControlLayout, MoveLayout
from control.rt.loop import Controller, LoopConfig
from control.rt.warmup import DECAY, MARGIN_NS, SEED_TICKS, Peak, WarmUp
from control.rt.wire import Wire
from hw.machine import MachineError, load_machine, parse_machine
from hw.sim.backend import SimBackend

UNIMATE = load_machine("unimate2000b")
TICKS = 4_500
MOVE_AT, MOVE_ROWS = 1_000, 1_200


@contextmanager
def live_controller(warm: bool, spin_ns: int | None = None
                    ) -> Iterator[tuple[Controller, Wire, SharedMemory, WarmUp | None]]:
    """A controller on a simulator of its own (lockstep, or real time spinning ``spin_ns``
    before each deadline), a warm-up beside it if ``warm``."""
    backend = SimBackend(UNIMATE, seed=7, lockstep=spin_ns is None)
    if spin_ns is not None:
        backend.clock.spin_ns = spin_ns
    ours, theirs = socket.socketpair()
    layout = ControlLayout(UNIMATE.n_joints)
    segment = shm.create("warmtest", layout.size)
    layout.write_header(segment.buf)
    controller = Controller(UNIMATE, backend, controller_end(theirs), segment.buf,
                            LoopConfig(period_ns=1_000_000, heartbeat_timeout_ns=10**15,
                                       orphan_timeout_ns=10**15))
    warm_up = WarmUp(controller) if warm else None
    controller.warm_up = warm_up
    backend.open()
    controller.start()
    controller.deadline = controller.clock.now_ns() + controller.config.period_ns
    client = client_end(ours)
    try:
        yield controller, client, segment, warm_up
    finally:
        if warm_up is not None:
            warm_up.close()
        controller.release()
        shm.release(segment, unlink=True)
        client.close()


def run_scenario(warm: bool) -> tuple[list[tuple], list[tuple], list[float], int]:
    """``TICKS`` cycles of the loop: jogs, a streamed jog, manual duty, a path move, the
    client's E-stop and a reset. Returns every tick's (valve duties, joint readings, mode),
    the events the client received, the simulated joints at the end, and the shadow's ticks."""
    trace, events = [], []
    with live_controller(warm) as (controller, client, segment, warm_up):
        words = controller.layout.client_words(segment.buf)
        move = None
        for k in range(TICKS):
            if k == 20:
                client.send(SetSpeedMode("automatic"))
            elif k == 50:
                client.send(JogPosition(0, 30.0))
            elif 400 <= k < 900 and k % 50 == 0:
                client.send(JogVelocity((0.0, 8.0, 0.0, -6.0, 0.0, 0.0)))
            elif k == 900:
                client.send(JogVelocity((0.0,) * 6))
            elif k == MOVE_AT:
                move = start_move(controller, client)
            elif k == 3_000:
                words[ESTOP_WORD] += 1
            elif k == 3_100:
                client.send(Reset())
            elif k == 3_200:
                client.send(Manual((0.0, 0.0, 30.0, 0.0, 0.0, -30.0)))
            elif k == 3_600:
                client.send(Hold())
            elif k == 3_700:
                client.send(JogPosition(2, -4.0))
            controller.cycle()
            modes = controller.modes
            trace.append((tuple(controller.valve), tuple(controller.encoders.position),
                          modes.mode))
            while client.poll(0):
                event = client.recv().record
                events.append((event.KIND, event.payload))
        words.release()
        positions = controller.backend.joint_positions()
        ran = warm_up.ran if warm_up is not None else 0
        if move is not None:
            shm.release(move, unlink=True)
    return trace, events, positions, ran


def start_move(controller: Controller, client: Wire) -> SharedMemory:
    """A closed-loop path from where the joints read now: Rotate and Bend 6° in 1.2 s."""
    start = np.array(controller.encoders.position)
    ramp = 0.5 - 0.5 * np.cos(np.linspace(0.0, np.pi, MOVE_ROWS))
    path = np.repeat(start[None, :], MOVE_ROWS, axis=0)
    path[:, 1] += 6.0 * ramp
    path[:, 3] -= 6.0 * ramp
    layout = MoveLayout(MOVE_ROWS, UNIMATE.n_joints, settle_rows=300)
    segment = shm.create("warmmove", layout.size)
    layout.write_header(segment.buf)
    client.send(StartMove(1, segment.name, "path", False, MOVE_ROWS),
                fds=(sealed.seal(path),))
    return segment


def test_the_live_loop_is_bit_for_bit_the_same_with_the_warm_up() -> None:
    """Every tick's duties and readings, every event and the simulated arm at the end match,
    with a shadow ticked before every live tick; and the scenario moved the arm (a jog, a
    streamed jog, a path move that completed, an E-stop and its reset, manual duty)."""
    without, events_without, end_without, _ = run_scenario(warm=False)
    with_warm_up, events_with, end_with, ran = run_scenario(warm=True)
    assert ran == TICKS
    kinds = [kind for kind, _ in events_without]
    assert "move_done" in kinds and "estop" in kinds, kinds
    done = next(p for kind, p in events_without if kind == "move_done")
    assert done["status"] == "complete", done
    duties = np.array([valve for valve, _, _ in without])
    readings = np.array([position for _, position, _ in without])
    assert np.count_nonzero(duties) > TICKS  # the valves were open for a while
    assert np.ptp(readings, axis=0)[[0, 1, 3]].min() > 5.0  # joints travelled
    for k, (a, b) in enumerate(zip(without, with_warm_up, strict=True)):
        assert a == b, f"tick {k}: without {a}, with the warm-up {b}"
    assert events_with == events_without
    assert end_with == end_without


def test_the_shadow_never_touches_the_live_backend_memory_or_channel() -> None:
    """Thousands of shadow ticks (each a full tick of its own, a jog among them) leave the
    live simulator, the live control segment, its outbox and its channel as they were."""
    with live_controller(warm=True) as (controller, client, segment, warm_up):
        controller.cycle()
        backend = controller.backend
        before = (bytes(segment.buf), backend.joint_positions(), backend.applied_duty(),
                  backend.chamber_pressures(), backend.clock.now_ns(), list(controller.valve),
                  controller.tick_count, list(controller.modes.duty))
        warm_up.shadow.channel.deliver(JogPosition(1, 3.0))
        shadow_start = warm_up.backend.joint_positions()[1]
        for _ in range(3_000):
            warm_up.before(controller.deadline)
        after = (bytes(segment.buf), backend.joint_positions(), backend.applied_duty(),
                 backend.chamber_pressures(), backend.clock.now_ns(), list(controller.valve),
                 controller.tick_count, list(controller.modes.duty))
        assert warm_up.ran == 3_001 and warm_up.error == ""
        assert abs(warm_up.backend.joint_positions()[1] - shadow_start) > 2.0  # it jogged
        assert after == before
        assert controller.outbox.queue == [] and not client.poll(0)


def test_a_piece_starts_only_when_its_peak_fits_before_the_deadline() -> None:
    """In real time: a piece whose recent longest run (and the margin) does not fit before
    the deadline is not started: the window stops there, no shadow tick half done is
    thrown away, and the next window goes on from that piece."""
    with live_controller(warm=True, spin_ns=150_000) as (controller, _client, _segment,
                                                          warm_up):
        clock = controller.clock
        warm_up.window_ns = 10**10  # no sleep before the window: the test sets the deadline
        warm_up.peaks = [Peak(0.0) for _ in warm_up.pieces]
        warm_up.peaks[4].peak = 1e10  # a piece "known" to take 10 s
        warm_up.before(clock.now_ns() + 1_000_000_000)
        assert (warm_up.windows, warm_up.pieces_run, warm_up.next, warm_up.ran) == (1, 4, 4, 0)
        assert (warm_up.skipped, warm_up.late) == (0, 0)
        warm_up.before(clock.now_ns() + 1_000_000_000)  # no room for piece 4 at all
        assert (warm_up.windows, warm_up.skipped, warm_up.pieces_run) == (2, 1, 4)
        assert warm_up.peaks[4].peak < 1e10  # lowered toward its floor
        warm_up.peaks[4] = Peak(0.0)
        warm_up.before(clock.now_ns() + 20_000_000)
        assert warm_up.ran >= 1 and warm_up.shadow.tick_count == warm_up.ran + SEED_TICKS
        assert warm_up.error == "" and not controller.guards.latched


def test_a_window_too_short_for_any_piece_runs_none() -> None:
    """A deadline closer than the margin: nothing runs, so nothing can end late."""
    with live_controller(warm=True, spin_ns=150_000) as (controller, _client, _segment,
                                                          warm_up):
        warm_up.peaks = [Peak(0.0) for _ in warm_up.pieces]
        for _ in range(100):
            warm_up.before(controller.clock.now_ns() + MARGIN_NS // 2)
        assert (warm_up.windows, warm_up.skipped, warm_up.pieces_run) == (100, 100, 0)
        assert warm_up.late == 0


def test_a_peak_rises_at_once_and_falls_slowly_never_below_its_floor_for_lack_of_room(
        ) -> None:
    peak = Peak(10_000.0)
    peak.add(50_000.0)
    assert peak.peak == 50_000.0  # a cold run is remembered at once
    peak.add(10_000.0)
    assert peak.peak == 50_000.0 - 40_000.0 / DECAY
    for _ in range(1_000):
        peak.no_room()
    assert 10_000.0 <= peak.peak < 10_100.0
    assert peak.bound() == peak.peak + MARGIN_NS


def test_the_window_is_the_machine_files_share_of_the_period() -> None:
    """``warm_up_pct`` of the period before each deadline, at least the clock's spin; none
    for a machine file without it, or on a lockstep clock; out of range, refused."""
    assert UNIMATE.warm_up_pct == load_machine("rig").warm_up_pct == 30.0
    with live_controller(warm=True, spin_ns=150_000) as (controller, *_):
        warm_up = WarmUp.beside(controller)
        assert warm_up is not None and warm_up.window_ns == 300_000
        warm_up.close()
        controller.clock.spin_ns = 400_000
        warm_up = WarmUp.beside(controller)
        assert warm_up is not None and warm_up.window_ns == 400_000
        warm_up.close()
        controller.machine = replace(UNIMATE, warm_up_pct=0.0)
        assert WarmUp.beside(controller) is None
    with live_controller(warm=False) as (controller, *_):
        assert WarmUp.beside(controller) is None
    text = UNIMATE.path.read_text()
    assert "warm_up_pct = 30.0" in text
    with pytest.raises(MachineError, match=r"machine\.warm_up_pct: 80 out of range"):
        parse_machine(text.replace("warm_up_pct = 30.0", "warm_up_pct = 80", 1), UNIMATE.path)


def test_a_shadow_that_fails_is_dropped_and_the_live_loop_goes_on() -> None:
    with live_controller(warm=True) as (controller, client, _segment, warm_up):
        warm_up.shadow.encoders = None  # a bug in the shadow's tick
        controller.cycle()
        controller.cycle()
        assert controller.warm_up is None and "AttributeError" in warm_up.error
        assert controller.tick_count == 2 and not controller.guards.latched
        received = []
        while client.poll(0):
            received.append(client.recv().record)
        assert any(isinstance(e, Notice) and "warm-up tick off" in e.message
                   for e in received), received


def test_a_shadow_that_fails_while_timed_at_the_start_is_dropped_at_the_first_window(
        ) -> None:
    """``seed`` times the pieces before any window: an error there raises nothing (the
    control process would not start); the loop drops the warm-up at its first cycle."""
    with live_controller(warm=True) as (controller, client, _segment, warm_up):
        warm_up.shadow.encoders = None
        warm_up.seed()
        assert "AttributeError" in warm_up.error
        controller.cycle()
        assert controller.warm_up is None and controller.tick_count == 1
        assert not controller.guards.latched and client.poll(1.0)


def test_a_shadow_whose_simulator_faults_holds_again() -> None:
    """A fault of the shadow's own (a pressed E-stop on its simulator) is reset, so it goes
    on warming the code of a loop that holds; the live loop sees nothing of it."""
    with live_controller(warm=True) as (controller, client, _segment, warm_up):
        warm_up.backend.press_estop(True)
        controller.cycle()
        assert warm_up.shadow.guards.latched
        warm_up.backend.press_estop(False)
        controller.cycle()
        assert not warm_up.shadow.guards.latched and warm_up.error == ""
        assert not controller.guards.latched and not client.poll(0)
