"""The control subprocess, for real: started by ControlClient on the simulator.

Lockstep clients run the simulator as fast as it computes (moves take a
fraction of their duration); real-time clients run the 1 kHz loop as the
operator gets it. Every test ends with no servodesk segment left in /dev/shm.
"""

from __future__ import annotations

import itertools
import json
import os
import signal
import subprocess
import sys
import textwrap
import threading
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from control import ControlClient, ControllerError, Flag, Mode
from control.client import Event
from control.identify.sysid import DeadbandModel
from control.motion import moves
from control.motion.acceptance import check_path
from control.motion.plan import path_rows
from control.recorder import as_written, load_run, table_text
from control.rt import shm
from control.rt.events import EStop
from control.rt.layout import ControlLayout
from control.rt.seqlock import SeqlockReader
from hw.machine import load_machine
from tests.control.waiting import wait_until

UNIMATE = load_machine("unimate2000b")
STEPS = {"inout": 120.0, "rotate": 20.0, "updown": 8.0, "bend": 30.0, "yaw": 30.0, "swivel": 40.0}



def our_segments(pid: int) -> list[str]:
    return [n for n in shm.leftover_segments() if shm.owner_pid(n) == pid]


@pytest.mark.parametrize("joint", list(STEPS))
def test_a_step_on_each_joint_settles_inside_its_tolerance(lockstep: ControlClient,
                                                           joint: str) -> None:
    j = UNIMATE.joint_index(joint)
    start = lockstep.status().position
    path = moves.step(start, j, start[j] + STEPS[joint], duration=8.0, machine=UNIMATE)
    result = lockstep.wait(lockstep.move(path, kind="step"), timeout=60)
    assert result.complete, result.status
    run = result.run
    (summary,) = [s for s in moves.summary(run.t, run.desired, run.actual, UNIMATE.joints)
                  if s.joint == UNIMATE.joints[j].name]
    assert summary.settling_time_s is not None, summary
    assert abs(run.actual[-1, j] - path[-1, j]) <= UNIMATE.joints[j].tolerance


def test_follow_track_completes_and_the_run_is_saved(lockstep: ControlClient,
                                                     tmp_path: Path) -> None:
    start = np.array(lockstep.status().position)
    end = start.copy()
    end[1] += 30.0
    path = moves.sine(start, end, period=2.0, duration=3.0, machine=UNIMATE)
    result = lockstep.wait(lockstep.move(path, kind="sine", meta={"period_s": 2.0}), timeout=60)
    assert result.complete and result.files is not None
    assert result.files.json.parent == tmp_path
    saved = load_run(result.files.json)
    assert saved.kind == "sine" and saved.machine == "unimate2000b"
    assert path_rows(saved) == len(path) < len(saved.t)  # then the settle's rows
    assert saved == as_written(result.run)
    np.testing.assert_allclose(result.run.desired[:len(path)], path, atol=1e-9)
    np.testing.assert_allclose(result.run.desired[len(path):], [path[-1]] * (len(saved.t)
                                                                            - len(path)))
    assert saved.coefficients["track"]["kp"] == [list(k) for k in UNIMATE.track.kp]
    tsv_rows = table_text(result.files.tsv).strip().splitlines()
    assert len(tsv_rows) == len(saved.t) and len(tsv_rows[0].split("\t")) == 1 + 3 * 6
    status = lockstep.status()
    assert status.mode == Mode.HOLD and not status.moving
    np.testing.assert_allclose(status.desired, path[-1], atol=1e-9)


def test_a_path_that_starts_away_gets_an_approach_and_the_tuis_summary(
        lockstep: ControlClient) -> None:
    here = np.array(lockstep.status().position)
    start = here.copy()
    start[1] += 20.0  # Rotate 20° away from where it is
    path = moves.step(start, 2, start[2] + 5.0, duration=3.0, machine=UNIMATE)
    result = lockstep.wait(lockstep.move(path, kind="step"), timeout=60)
    assert result.complete, result.status
    plan = result.plan
    assert plan.approach > 0 and path_rows(result.run) == plan.approach + len(path)
    assert abs(result.run.desired[0, 1] - here[1]) < 1.0  # the approach starts where Rotate was
    rows = result.summaries()
    assert [label for label, _ in rows] == ["Up/Down"]  # Rotate moved only in the approach
    assert rows[0][1].step == pytest.approx(5.0)
    (saved,) = load_run(result.files.json).meta["results"]  # the same metrics, in the JSON
    assert saved["label"] == "Up/Down" and saved["metric"] == "step"
    assert saved["step"] == pytest.approx(5.0)
    # as the JSON writes numbers: 10 significant digits (control/recorder.py JSON_DIGITS)
    assert saved["settling_time_s"] == pytest.approx(rows[0][1].settling_time_s, rel=1e-9)


def test_a_jump_is_refused_as_a_path_and_runs_as_a_step(lockstep: ControlClient,
                                                         new_segments) -> None:
    """The acceptance rules by kind (control/motion/acceptance.py): Up/Down jumping 5° in one
    sample is refused as a smooth path, nothing sent, and accepted as a step."""
    start = np.array(lockstep.status().position)
    path = np.tile(start, (1500, 1))
    path[300:, 2] += 5.0
    with pytest.raises(ValueError, match=r"^Up/Down moves \+5 deg in 0.001 s at sample 300 "
                                         r"\(t = 0.300 s\): 5000 deg/s, 200 times its max_speed "
                                         r"25 deg/s .*send it as a step move \(kind 'step'\)"):
        lockstep.move(path)
    assert new_segments() == [lockstep.segment_name]
    assert lockstep.status().move_id == 0 and lockstep.status().mode == Mode.HOLD
    result = lockstep.wait(lockstep.move(path, kind="step"), timeout=60)
    assert result.complete, result.status
    assert path_rows(result.run) == len(path) and result.plan.approach == 0
    assert abs(result.run.actual[-1, 2] - path[-1, 2]) <= UNIMATE.joints[2].tolerance


def test_a_smooth_move_that_starts_away_runs_behind_a_smooth_approach(
        lockstep: ControlClient) -> None:
    """A sine whose first row is 20° of Rotate away: the client puts the approach in front,
    and what the controller was sent keeps every joint's max_speed and max_accel."""
    here = np.array(lockstep.status().position)
    start = here.copy()
    start[1] += 20.0
    end = start.copy()
    end[2] += 5.0
    path = moves.sine(start, end, period=2.0, duration=2.0, machine=UNIMATE)
    result = lockstep.wait(lockstep.move(path, kind="sine"), timeout=60)
    assert result.complete, result.status
    sent = result.run.desired[:path_rows(result.run)]
    assert result.plan.approach > 0 and len(sent) == result.plan.approach + len(path)
    assert np.abs(sent[0] - here).max() < 1e-9
    np.testing.assert_allclose(sent[result.plan.approach:], path, atol=1e-9)
    check_path(sent, "sine", UNIMATE, lockstep.dt)


def test_jog_duty_reaches_the_backend(realtime: ControlClient) -> None:
    # Swivel, slowly: seconds from any limit, so a loaded machine's late look still sees it
    realtime.jog_joint(5, 25.0)
    polarity = UNIMATE.joints[5].polarity
    wait_until(lambda: realtime.status().valve[5] == polarity * 25.0, 3.0, "jog duty at the valve")
    status = realtime.status()
    assert status.mode == Mode.MANUAL_ACTUATE and status.duty[5] == 25.0
    realtime.jog([0.0] * 6)
    wait_until(lambda: realtime.status().valve == (0.0,) * 6, 3.0, "zero duty")


def test_estop_closes_every_valve_on_the_tick_it_arrives(realtime: ControlClient) -> None:
    realtime.jog([40.0] * 6)
    wait_until(lambda: all(realtime.status().valve), 1.0, "valves open")
    realtime.estop()
    event = realtime.wait_event("estop", timeout=2.0)
    assert event.payload["latched"] and event.payload["reason"] == "operator E-stop"
    status = realtime.status()
    assert status.estop and status.valve == (0.0,) * 6 and status.duty == (0.0,) * 6
    realtime.jog([40.0] * 6)
    assert "refused: E-stop latched" in realtime.wait_event("refused", 2.0).message
    assert realtime.status().valve == (0.0,) * 6
    realtime.reset()
    wait_until(lambda: not realtime.status().estop, 1.0, "E-stop released")
    assert realtime.status().mode == Mode.HOLD


def test_estop_input_latches_and_blocks_reset_while_pressed(realtime: ControlClient) -> None:
    realtime.jog([30.0] * 6)
    realtime.inject("press_estop", True)
    event = realtime.wait_event("estop", timeout=2.0)
    assert event.payload["reason"] == "E-stop input pressed"
    assert realtime.status().valve == (0.0,) * 6
    realtime.reset()
    assert "still pressed" in realtime.wait_event("refused", 2.0).message
    assert realtime.status().estop
    realtime.inject("press_estop", False)
    realtime.reset()
    wait_until(lambda: not realtime.status().estop, 1.0, "E-stop released")


def test_a_reset_with_nothing_latched_is_refused_and_the_move_runs_on(
        realtime: ControlClient) -> None:
    """A reset is the E-stop's release: with none latched it is refused. Its hold stopped a
    running move's arm before and left the move running (moving, mode HOLD), never ending."""
    start = realtime.status().position
    move = realtime.move(moves.step(start, 0, start[0] + 20, duration=1.0, machine=UNIMATE),
                         kind="step")
    wait_until(lambda: realtime.status().move_done > 200, 3.0, "the move to run")
    realtime.reset()
    assert "no E-stop is latched" in realtime.wait_event("refused", 2.0).message
    assert realtime.wait(move, timeout=10).complete


def test_estop_during_a_move_ends_it_and_saves_what_ran(realtime: ControlClient) -> None:
    start = realtime.status().position
    move = realtime.move(moves.step(start, 0, start[0] + 200, duration=5.0, machine=UNIMATE),
                         kind="step")
    wait_until(lambda: realtime.status().move_done > 200, 3.0, "the move to run")
    realtime.estop()
    result = realtime.wait(move, timeout=5)
    assert result.status == "estop: operator E-stop"
    assert result.files is not None and 0 < len(result.run.t) < 5000


def test_coefficients_change_during_a_move(lockstep: ControlClient) -> None:
    """A set applied while a move runs takes effect at once. The gain check's first call in a
    process imports scipy.signal (seconds under load, while the lockstep move runs on flat
    out: beside a CPU burner it ended before the set was applied); made before the move."""
    from control.identify import gains

    gentle = UNIMATE.track.__class__(**{**UNIMATE.track.__dict__, "duty_limit": 5.0})
    assert gains.check(gentle, UNIMATE, lockstep.models, lockstep.dt).ok
    start = np.array(lockstep.status().position)
    path = moves.multi_step(start, start + np.array([50, 10, 5, 10, 10, 10]), duration=20.0,
                            machine=UNIMATE)
    move = lockstep.move(path, kind="multi_step")
    wait_until(lambda: lockstep.status().move_done > 100, 10.0, "the move to run")
    lockstep.set_coefficients("track", gentle)
    wait_until(lambda: max(map(abs, lockstep.status().duty)) <= 5.0, 5.0, "the new set applied")
    assert lockstep.status().moving
    lockstep.hold()
    assert lockstep.wait(move, timeout=10).status == "aborted by operator"


def applied(client: ControlClient, which: str) -> object:
    """The set the controller reads from shared memory."""
    segment = shm.attach(client.segment_name)
    reader = SeqlockReader(segment.buf, client.layout.coefficient_offset(which),
                           client.layout.coefficients.struct)
    try:
        return client.layout.coefficients.decode(reader.read(), which)
    finally:
        reader.release()
        shm.release(segment, unlink=False)


def small_ramp(client: ControlClient) -> np.ndarray:
    start = np.array(client.status().position)
    return moves.ramp(start, start + np.array([0.0, 5.0, 0.0, 0.0, 0.0, 0.0]), 1.0, 1.5,
                      machine=UNIMATE)


@pytest.mark.parametrize("kp", [-20.0, 1e9])
def test_gains_that_cannot_be_stable_are_refused_and_nothing_is_applied(
        lockstep: ControlClient, kp: float) -> None:
    track = UNIMATE.track
    wild = replace(track, name="wild", kp=((kp,),) * 6)
    before = applied(lockstep, "track")
    with pytest.raises(ValueError, match=r"^coefficient set 'wild' refused, nothing applied: "
                                         r"In/Out: unstable on the nominal model: .*Swivel: "
                                         r"unstable"):
        lockstep.set_coefficients("track", wild)
    assert lockstep.coefficients["track"] == track and applied(lockstep, "track") == before
    result = lockstep.wait(lockstep.move(small_ramp(lockstep), kind="ramp"), timeout=60)
    assert result.complete, result.status
    saved = load_run(result.files.json).coefficients["track"]
    assert saved["kp"] == [list(k) for k in track.kp] and saved["check"]["passed"] is None
    assert [e for e in lockstep.poll_events() if e.kind in ("refused", "notice", "fault")] == []


def test_an_override_applies_a_refused_set_and_every_run_says_so(lockstep: ControlClient,
                                                                 tmp_path: Path) -> None:
    """Bend at kp 105: Ms 10.4 on the nominal model (refused), 2.5 on the Bend identified on
    the simulator; an expert overrides with that reason, and the run made with the set
    carries the reason and the refusal in its saved JSON."""
    bend = replace(UNIMATE.track, name="stiff bend",
                   kp=tuple((105.0,) if j == 3 else k for j, k in enumerate(UNIMATE.track.kp)))
    with pytest.raises(ValueError, match="Bend: too little margin on the nominal model"):
        lockstep.set_coefficients("track", bend)
    with pytest.raises(ValueError, match="override needs the reason"):
        lockstep.set_coefficients("track", bend, override=" ")
    reason = "Bend identified at 35 Hz: Ms 2.5 on that model"
    check = lockstep.set_coefficients("track", bend, override=reason)
    assert not check.ok and lockstep.coefficients["track"] is bend
    assert applied(lockstep, "track").kp[3] == (105.0,)
    notice = lockstep.wait_event("notice", 2.0)
    assert reason in notice.message and "Bend: too little margin" in notice.message
    result = lockstep.wait(lockstep.move(small_ramp(lockstep), kind="ramp"), timeout=60)
    assert result.complete, result.status
    saved = json.loads(result.files.json.read_text())["coefficients"]["track"]
    assert saved["kp"][3] == [105.0] and saved["name"] == "stiff bend"
    assert saved["check"]["passed"] is False and saved["check"]["overridden"] is True
    assert saved["check"]["override_reason"] == reason
    assert saved["check"]["summary"].startswith("Bend: too little margin on the nominal model")
    lockstep.set_coefficients("track", UNIMATE.track)  # checked again: passes
    result = lockstep.wait(lockstep.move(small_ramp(lockstep), kind="ramp"), timeout=60)
    assert load_run(result.files.json).coefficients["track"]["check"]["passed"] is True


def test_a_set_is_judged_on_the_identified_models_the_client_was_given(
        lockstep: ControlClient) -> None:
    """The same stiff Bend passes on an identified Bend model (Ms 2.5 ≤ 6), and later sets
    (a Tuning tab edit) are judged on that model too."""
    identified = DeadbandModel("Bend", "deg", k_pos=1.211, d_pos=27.5, k_neg=1.19, d_neg=24.3,
                               wn=2 * np.pi * 35.2, zeta=0.49)
    bend = replace(UNIMATE.track, name="stiff bend",
                   kp=tuple((105.0,) if j == 3 else k for j, k in enumerate(UNIMATE.track.kp)))
    check = lockstep.set_coefficients("track", bend, [None, None, None, identified, None, None])
    assert check.ok and check.joints[3].model == "identified"
    assert lockstep.models[3] == identified and lockstep.models[0] is None
    edited = replace(bend, duty_limit=80.0)
    assert lockstep.set_coefficients("track", edited).joints[3].model == "identified"
    assert applied(lockstep, "track").duty_limit == 80.0


def test_two_clients_in_one_process_have_their_own_segments(tmp_path: Path, new_segments
                                                             ) -> None:
    with ControlClient("rig", lockstep=True, data_dir=tmp_path, heartbeat_timeout_s=3.0) as one, \
            ControlClient("unimate2000b", lockstep=True, data_dir=tmp_path,
                          heartbeat_timeout_s=3.0) as two:
        assert one.segment_name != two.segment_name
        assert len(one.status().position) == 1 and len(two.status().position) == 6
    assert new_segments() == []


def test_a_closed_client_says_so_when_read(tmp_path: Path) -> None:
    """Its status and histogram after close: a clear ControllerError, not the released
    memory's ValueError (a servo thread begun as its client closed died of it, c7d6da4)."""
    client = ControlClient("rig", lockstep=True, data_dir=tmp_path)
    client.status()
    client.close()
    for read in (client.status, client.histogram):
        with pytest.raises(ControllerError, match="this client is closed"):
            read()


def test_close_while_a_listener_is_busy_delivers_the_events_in_order_from_one_thread(
        tmp_path: Path) -> None:
    """A listener still busy with one event when the client closes (a loaded UI): the events
    behind it are delivered after it, by the event thread. close() used to wait 0.2 s for that
    thread and then read the channel itself, calling the listener from two threads at once
    (and polling the channel from both: "concurrent poll() invocation" under load)."""
    calls: list[tuple[bool, str, float, float]] = []
    busy = threading.Event()

    def listener(event: Event) -> None:
        if not isinstance(event.record, EStop):
            return
        start = time.monotonic()
        if event.record.latched:
            busy.set()
            time.sleep(0.5)  # the listener is busy when close() comes (asserted)
        calls.append((event.record.latched, threading.current_thread().name, start,
                      time.monotonic()))

    client = ControlClient("rig", lockstep=True, data_dir=tmp_path)
    client.on_event = listener
    client.estop()
    assert busy.wait(10.0), "no E-stop event reached the listener"
    client.reset()
    wait_until(lambda: not client.status().estop, 10.0, "the reset")
    closing = time.monotonic()
    client.close()
    assert closing < calls[0][3], f"close() came after the listener was done: {calls}"
    # latched (the E-stop word, then its message: the controller latches on each), released
    assert [latched for latched, *_ in calls] == [True, True, False], calls
    assert len({thread for _, thread, *_ in calls}) == 1, f"delivered from two threads: {calls}"
    assert all(later[2] >= earlier[3] for earlier, later in itertools.pairwise(calls)), (
        f"an event was delivered during the one before: {calls}")


def test_bad_paths_are_refused_before_anything_starts(lockstep: ControlClient,
                                                      new_segments) -> None:
    start = np.array(lockstep.status().position)
    path = np.tile(start, (100, 1))
    path[40, 2] = 35.0
    with pytest.raises(ValueError, match=r"Up/Down target 35° is outside -27…30° "
                                         r"\(machine unimate2000b\) at sample 40"):
        lockstep.move(path)
    path[40, 2] = np.nan
    with pytest.raises(ValueError, match="Up/Down target nan is not a number"):
        lockstep.move(path)
    with pytest.raises(ValueError, match=r"a path is \(N, 6\)"):
        lockstep.move(path[:, :3])
    assert new_segments() == [lockstep.segment_name]
    assert lockstep.status().mode == Mode.HOLD


def test_following_error_aborts_into_hold_naming_the_joint(lockstep: ControlClient) -> None:
    start = np.array(lockstep.status().position)
    lockstep.inject("jam_valve", 1, 0.7)  # Rotate's valve opens to 30 % of its duty
    path = moves.step(start, 1, start[1] + 30.0, duration=3.0, machine=UNIMATE)
    result = lockstep.wait(lockstep.move(path, kind="step"), timeout=60)
    assert result.status.startswith("fault: following error: Rotate is "), result.status
    fault = lockstep.wait_event("fault", 5.0, lambda e: e.payload["kind"] == "following_error")
    assert fault.payload["joint"] == 1
    assert lockstep.status().mode == Mode.HOLD


def test_a_joint_driven_into_its_limit_stops_there(lockstep: ControlClient) -> None:
    lockstep.jog_joint(2, 60.0)
    fault = lockstep.wait_event("fault", 30.0, lambda e: e.payload["kind"] == "limit")
    assert fault.payload["joint"] == 2 and fault.message.startswith("Up/Down at ")
    wait_until(lambda: lockstep.status().valve[2] == 0.0, 2.0, "the joint's valve closed")
    assert lockstep.status().position[2] <= UNIMATE.joints[2].upper + 0.5


def test_killing_the_controller_is_reported(realtime: ControlClient) -> None:
    start = realtime.status().position
    move = realtime.move(moves.step(start, 1, start[1] + 30, duration=5.0, machine=UNIMATE),
                         kind="step")
    wait_until(lambda: realtime.status().move_done > 300, 3.0, "the move to run")
    os.kill(realtime.pid, signal.SIGKILL)
    died = realtime.wait_event("died", timeout=5.0)
    assert "controller died" in died.message
    result = realtime.wait(move, timeout=5)
    assert result.status == "interrupted: controller died"
    assert result.files is not None and len(result.run.t) > 300
    with pytest.raises(ControllerError, match="controller died"):
        realtime.jog([10.0] * 6)


CLIENT_SCRIPT = textwrap.dedent("""
    import sys, time
    from control import ControlClient, Mode
    client = ControlClient("unimate2000b", data_dir=sys.argv[1], orphan_timeout_s=0.5)
    client.jog([30.0] * 6)
    while client.status().mode != Mode.MANUAL_ACTUATE:
        time.sleep(0.002)
    print(client.pid, client.segment_name, flush=True)
    time.sleep(60)
""")


def test_killing_the_client_makes_the_controller_hold_then_clean_up(tmp_path: Path) -> None:
    """The client's script says where its controller is once it jogs; killed, the controller
    holds, then exits after its orphan timeout (0.5 s: its length is test_client_loss's
    subject, not this test's) and leaves none of the client's segments."""
    script = subprocess.Popen([sys.executable, "-c", CLIENT_SCRIPT, str(tmp_path)],
                              stdout=subprocess.PIPE, text=True)
    try:
        pid, name = script.stdout.readline().split()
        controller_pid = int(pid)
        segment = shm.attach(name)
        layout = ControlLayout(6)
        reader = SeqlockReader(segment.buf, layout.status_offset, layout.status.struct)
        assert layout.status.decode(reader.read()).mode == Mode.MANUAL_ACTUATE
        script.kill()
        script.wait(5)

        def holding() -> bool:
            status = layout.status.decode(reader.read())
            return status.mode == Mode.HOLD and bool(status.flags & Flag.UI_LOST)

        wait_until(holding, 2.0, "the controller to hold after losing its client")
        reader.release()
        shm.release(segment, unlink=False)
        wait_until(lambda: not shm.pid_alive(controller_pid), 10.0, "the orphan to exit")
        assert our_segments(script.pid) == []
    finally:
        script.kill()
        script.wait(5)


def test_the_rig_refuses_moves_until_initialised_then_steps(tmp_path: Path, new_segments
                                                            ) -> None:
    rig = load_machine("rig")
    with ControlClient(rig, lockstep=True, data_dir=tmp_path, heartbeat_timeout_s=3.0,
                       sim_options={"initial": [400.0]}) as client:
        assert not client.status().homed
        path = moves.step(client.status().position, 0, 100.0, duration=2.0, machine=rig)
        assert client.wait(client.move(path, kind="step"), 10).status.startswith(
            "refused: not initialised")
        client.initialise()
        done = client.wait_event("initialised", 60.0)
        assert done.payload["status"].startswith("complete: initialised")
        status = client.status()
        assert status.homed and abs(status.position[0]) < 1.0
        result = client.wait(client.move(moves.step(status.position, 0, 400.0, duration=4.0,
                                                     machine=rig), kind="step"), 30)
        assert result.complete
        assert abs(result.run.actual[-1, 0] - 400.0) < 5.0
    assert new_segments() == []


@pytest.mark.parametrize(("call", "args"), [
    ("jog_position", (-1, 10.0)),
    ("jog_position", (6, 1.0)),
    ("jog_position", ("elbow", 1.0)),
    ("jog_position", (1, float("nan"))),
    ("jog_joint", (6, 10.0)),
    ("jog_joint", (-1, 10.0)),
    ("jog_joint", (0, float("inf"))),
    ("jog", ([10.0] * 5,)),
])
def test_a_joint_that_does_not_exist_or_a_bad_number_is_a_value_error_and_sends_nothing(
        realtime: ControlClient, call: str, args: tuple) -> None:
    before = realtime.status()
    with pytest.raises(ValueError, match=r"no joint|number|duties"):
        getattr(realtime, call)(*args)
    realtime.hold()  # a command behind it: anything sent before it would have been handled
    wait_until(lambda: realtime.status().tick > before.tick + 50, 3.0, "ticks after the call")
    status = realtime.status()
    assert not status.estop and status.mode == Mode.HOLD, status.fault
    assert [e for e in realtime.poll_events() if e.kind in ("refused", "estop")] == []


def test_a_joint_may_be_named(realtime: ControlClient) -> None:
    start = realtime.status().position[2]
    realtime.jog_position("updown", 1.0)
    wait_until(lambda: abs(realtime.status().position[2] - (start + 1.0)) < 0.2, 5.0,
               "Up/Down to move 1° by name")


JOG_DEG = 15.0  # the position jog's travel


def test_a_position_jog_past_the_following_error_travels_at_jog_speed_and_trips_nothing(
        realtime: ControlClient) -> None:
    """The bug this replaces: a position jog moved Up/Down's hold target 25° at once, the
    duty saturated and the following error latched the E-stop. Now the target travels at
    the joint's jog speed and the joint follows it. 15°: more than Up/Down's 12° following
    error, as 25° was, in 2.4 s rather than 4 (a jump of it fails the slope at once). In
    real time, so that the status is sampled all along the jog however loaded the machine."""
    joint = UNIMATE.joints[2]
    assert joint.following_error < JOG_DEG
    start = realtime.status().desired[2]  # the jog moves the hold target, not the reading
    realtime.jog_position(2, JOG_DEG)
    goal = min(start + JOG_DEG, joint.upper)
    seen = []  # (controller tick, hold target) while the target travels
    deadline = time.monotonic() + 60.0
    while abs((status := realtime.status()).desired[2] - goal) > 1e-9:
        seen.append((status.tick, status.desired[2]))
        assert time.monotonic() < deadline, "the hold target never reached the goal"
        time.sleep(0.001)  # a loop that never sleeps starves the client's heartbeat thread
    tick, target = np.array(seen).T
    moved = np.flatnonzero(np.diff(tick) > 0)
    slope = np.abs(np.diff(target)[moved] / (np.diff(tick)[moved] * UNIMATE.sample_time_s))
    assert len(moved) > 10 and slope.max() <= joint.jog_speed * 1.01, slope.max()
    wait_until(lambda: abs(realtime.status().position[2] - goal) < 3 * joint.tolerance, 60.0,
               "Up/Down to follow")
    status = realtime.status()
    assert not status.estop and status.fault == "", status.fault
    assert [e.message for e in realtime.poll_events() if e.kind == "fault"] == []


def test_go_to_plans_a_joint_space_move_at_the_speed_asked(lockstep: ControlClient) -> None:
    here = np.array(lockstep.status().position)
    goal = here + np.array([100.0, 20.0, 5.0, -20.0, 15.0, 30.0])
    result = lockstep.wait(lockstep.go_to(goal, speed=0.5), timeout=60)
    assert result.complete and result.run.kind == "go_to", result.status
    assert np.abs(result.run.actual[-1] - goal).max() < 2.0
    speed = np.abs(np.diff(result.run.desired, axis=0)).max(axis=0) / lockstep.dt
    assert np.all(speed <= 0.5 * np.array([j.max_speed for j in UNIMATE.joints]) * 1.01)
    with pytest.raises(ValueError, match="Up/Down target 99° is outside"):
        lockstep.go_to([*goal[:2], 99.0, *goal[3:]])

