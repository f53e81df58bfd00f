"""What a key does in each state an operator meets (the E-stop latched, a move running or in
feed hold, reduced speed (T1), the controller dead, an observer): the states where an audit
found a key moving the robot unasked, or saying nothing where the operator needed a reason.

Space on the Jog tab zeroes manual duties (option.c); anywhere else it must keep the joints in
closed-loop hold: it sent a 0 % manual duty, which let go of the held arm (desired NaN, every
valve at 0) in T1 too, aborted a running move into open loop, and took a held Cartesian jog's
servo out of hold, whose thread then died on the NaN target.

^S on the Moves tab, and the Identify tab's Run, looked only at their own move: another tab's,
running or in feed hold, was superseded by theirs. ^R with no E-stop latched asked to release
one, and its reset held a running move's arm while the move ran on. ^Y's switch to automatic
waited for the controller on the UI's thread: refused (a T1 jog travelling), it held every key
back 2 s, Esc too. The feed keys stepped from the TUI's own count, not from an override a
program's feed step had set: ^↓ at 50 % gave 90 %. With the controller dead, ^R and ^Y asked
their questions of it."""

from __future__ import annotations

import asyncio
import math
import os
import signal

import numpy as np

from app.tabs.identify import IdentifyTab
from app.tabs.jog import QUIET_STOPS
from app.tabs.moves import MovesTab
from app.widgets.dialogs import ConfirmScreen
from control.client import ControlClient
from control.motion import moves
from control.rt.commands import Hold, Manual
from control.rt.layout import Mode
from hw.machine import load_machine
from tests.app.conftest import PilotedApp
from tests.app.test_tui_moves import choose, field
from tests.app.test_tui_program import DriverPilot

SIZE = (160, 48)
UNIMATE = load_machine("unimate2000b")


def spy(client: ControlClient) -> list[object]:
    """Every command ``client`` sends from now on (it still sends them)."""
    sent: list[object] = []
    send = client._send
    client._send = lambda command, *fds: (sent.append(command), send(command, *fds))[1]
    return sent


def long_ramp(client: ControlClient):
    """A 20 s ramp of Rotate from where it is: a move another tab (Program, Positions) or
    client has running."""
    start = np.array(client.status().position)
    end = start.copy()
    end[1] += 20.0
    return client.move(moves.ramp(start, end, ramp_time=20.0, machine=UNIMATE), kind="ramp")


def test_space_in_t1_holds_the_arm_and_never_lets_go_of_it(tui, data_dir) -> None:
    """As the operator starts it: T1, the Jog tab in position mode. Space held the arm before
    only by luck of the valves: it put the controller in manual actuation at 0 %."""
    async def scenario() -> None:
        app = PilotedApp("unimate2000b", "sim", None, data_dir, lockstep=True,
                         client_options={"heartbeat_timeout_s": 2.0}, build_behind=False)
        async with app.run_test(size=SIZE) as pilot:
            pilot = DriverPilot(app)
            status = await tui.ready(app, pilot)
            assert status.speed_mode == "reduced"
            client = app.client
            pad = app.query_one("#jog-pad")
            await tui.until(lambda: pad.mode == "position", what="the pad in position mode")
            sent = spy(client)
            await pilot.press("space")
            await tui.until(lambda: sent, what="space to send a command")
            assert not any(isinstance(c, Manual) for c in sent), sent
            assert isinstance(sent[0], Hold), sent
            await tui.until(lambda: client.status().mode == Mode.HOLD, what="holding")
            assert all(math.isfinite(d) for d in client.status().desired)

    asyncio.run(scenario())


def test_space_in_duty_mode_holds_a_running_move_rather_than_drop_it_into_open_loop(
        tui) -> None:
    """Automatic, duty mode, no duty set, a move of another tab running: space stops it and
    holds (as ^G), where it ended the move 'aborted: manual actuation' at 0 % duty. In manual
    actuation it still zeroes every duty (option.c)."""
    async def scenario() -> None:
        app = tui.app(lockstep=False)  # real time: the ramp is still under way at space
        async with app.run_test(size=SIZE) as pilot:
            pilot = DriverPilot(app)
            await tui.ready(app, pilot)
            client = app.client
            assert app.query_one("#jog-pad").mode == "duty"
            handle = long_ramp(client)
            await tui.until(lambda: client.status().move_done > 100, what="the ramp under way")
            await pilot.press("space")
            result = await asyncio.to_thread(client.wait, handle, 10)
            assert result.status == "aborted by operator", result.status
            await tui.until(lambda: client.status().mode == Mode.HOLD, what="holding")
            assert all(math.isfinite(d) for d in client.status().desired)

            await pilot.press("5", "s")  # manual actuation: space zeroes its duties
            await tui.until(lambda: client.status().duty[1] == 5.0, what="Rotate at 5 %")
            await pilot.press("space")
            await tui.until(lambda: not any(client.status().duty), what="every duty 0")
            assert client.status().mode == Mode.MANUAL_ACTUATE

    asyncio.run(scenario())


def test_space_brakes_a_held_cartesian_jog_along_its_line_and_holds(tui) -> None:
    async def scenario() -> None:
        app = tui.app(lockstep=False)
        async with app.run_test(size=SIZE) as pilot:
            pilot = DriverPilot(app)
            await tui.ready(app, pilot)
            client = app.client
            tab = app.tab("jog")
            await pilot.press("w", "m", "9")  # world frame, hold-to-move, full jog speed
            await pilot.press("a")  # x +: the servo starts
            await tui.until(lambda: tab._servo is not None and tab._servo.running,
                            what="the held jog's servo running")
            servo, sent = tab._servo, spy(client)
            await pilot.press("space")
            report = await asyncio.to_thread(servo.wait, 5.0)
            assert report.stopped in QUIET_STOPS, report  # braked, not thrown out of hold
            assert not any(isinstance(c, Manual) for c in sent), sent
            await tui.until(lambda: client.status().mode == Mode.HOLD, what="holding")
            assert all(math.isfinite(d) for d in client.status().desired)
            await tui.until(lambda: any(e.kind == "jog" for e in app.desk.events.entries),
                            what="the held jog in the event log")

    asyncio.run(scenario())


def test_run_move_refuses_while_another_tabs_move_runs_or_stands_in_feed_hold(tui) -> None:
    """^S on the Moves tab checked only for its own move: with a move of the Program or the
    Positions tab (here the client's) held by ^F, it superseded that move, and the arm moved
    off from a feed hold; running, it changed the arm's path mid-move. Now it is refused with
    the reason, as the Positions tab's go-to and the Program tab's run are; once that move is
    held (^G) ^S runs the form's move."""
    async def scenario() -> None:
        app = tui.app(lockstep=False)  # real time: the ramp is still under way at ^S
        async with app.run_test(size=SIZE) as pilot:
            pilot = DriverPilot(app)
            status = await tui.ready(app, pilot)
            client = app.client
            await pilot.press("f2")
            await choose(app, pilot, "Step")
            app.query_one("#form-step JointField Select").value = 2  # Up/Down
            field(app, "step", "target").text = f"{status.position[2] + 5.0:.1f}"
            tab, error = app.query_one(MovesTab), app.query_one("#move-error")
            handle = long_ramp(client)
            await tui.until(lambda: client.status().move_done > 100, what="the ramp under way")
            await pilot.press("ctrl+f")
            await tui.until(lambda: client.status().paused, what="the feed hold")
            await pilot.press("ctrl+s")
            await tui.until(lambda: "feed hold" in str(error.render()),
                            what=lambda: f"the refusal in feed hold: {error.render()!s}")
            assert client.status().move_id == handle.move_id and client.status().paused
            assert tab.handle is None and not handle.done.is_set()

            await pilot.press("ctrl+f")  # resumed: running, still refused
            await tui.until(lambda: not client.status().paused, what="the resume")
            await pilot.press("ctrl+s")
            await tui.until(lambda: "a move is running" in str(error.render()),
                            what=lambda: f"the refusal while it runs: {error.render()!s}")
            assert client.status().move_id == handle.move_id and not handle.done.is_set()

            await pilot.press("ctrl+g")
            assert (await asyncio.to_thread(client.wait, handle, 10)).status == \
                "aborted by operator"
            await pilot.press("ctrl+s")  # nothing runs now: the form's step runs
            await tui.until(lambda: tab.handle is not None, what="the step started")
            await tui.until(lambda: tab.handle is None, timeout=30, what="the step's end")
            assert tab.last_result is not None and tab.last_result.complete, \
                tab.last_result and tab.last_result.status

    asyncio.run(scenario())


def test_release_with_no_estop_latched_says_so_and_leaves_a_running_move_alone(tui) -> None:
    """^R asked 'Release the E-stop?' with none latched; a yes sent the reset, whose hold
    stopped the arm of a running move and left the move 'running' (moving, in HOLD) with the
    Moves tab counting on. Now it says there is nothing to release, and the move ends."""
    async def scenario() -> None:
        app = tui.app(lockstep=False)  # real time: the ramp is still under way at ^R
        async with app.run_test(size=SIZE) as pilot:
            pilot = DriverPilot(app)
            await tui.ready(app, pilot)
            client = app.client
            seen = tui.notifications(app)
            start = np.array(client.status().position)
            end = start.copy()
            end[1] += 2.0
            handle = client.move(moves.ramp(start, end, ramp_time=1.0, machine=UNIMATE),
                                 kind="ramp")
            await tui.until(lambda: client.status().move_done > 100, what="the ramp under way")
            await pilot.press("ctrl+r")
            await tui.until(lambda: any("No E-stop is latched" in m for m in seen),
                            what=lambda: f"nothing to release, said: {seen}")
            assert not isinstance(app.screen, ConfirmScreen)
            assert (await asyncio.to_thread(client.wait, handle, 10)).complete

    asyncio.run(scenario())


def test_the_estop_is_taken_while_the_switch_to_automatic_waits_for_the_controller(
        tui, data_dir) -> None:
    """^Y, yes, during a T1 position jog's travel: the controller refuses automatic while a
    jog moves, and the switch waited for it on the UI's thread for 2 s, every key held back,
    Esc too (it latched 2.05 s after in a probe). Now the wait is a worker's: the E-stop
    latches before the switch has given up."""
    async def scenario() -> None:
        app = PilotedApp("unimate2000b", "sim", None, data_dir, lockstep=False,
                         client_options={"heartbeat_timeout_s": 2.0}, build_behind=False)
        async with app.run_test(size=SIZE) as pilot:
            pilot = DriverPilot(app)
            await tui.ready(app, pilot)  # as the operator starts it: T1, position jog
            client = app.client
            seen = tui.notifications(app)
            await pilot.press("9", "d")  # Up/Down 5° at its 6.25°/s jog speed
            await tui.until(lambda: abs(client.status().desired[2]
                                        - client.status().position[2]) > 0.05,
                            what="Up/Down's jog travelling")
            await pilot.press("ctrl+y")
            await tui.until(lambda: isinstance(app.screen, ConfirmScreen), what="the question")
            tui.post_key(app, "y")
            await tui.until(lambda: any("automatic (full speed) is set only at rest" in m
                                        for m in seen), what="the controller's refusal")
            assert not any("did not switch" in m for m in seen), seen  # it waits on
            tui.post_key(app, "ctrl+e")
            await tui.until(lambda: client.status().estop, what="the E-stop")
            assert not any("did not switch" in m for m in seen), seen  # taken meanwhile
            await tui.until(lambda: any("did not switch to automatic" in m for m in seen),
                            what=lambda: f"the switch's failure told: {seen}")
            assert client.speed_mode == "reduced"

    asyncio.run(scenario())


def test_identify_refuses_to_start_while_another_move_stands_in_feed_hold(tui) -> None:
    """The Identify tab's Run started its open-loop profile over a move held by ^F (it
    superseded it: the arm driven open loop from a feed hold); now it is refused, saying
    why, as the Moves tab's ^S is."""
    async def scenario() -> None:
        app = tui.app(lockstep=False)  # real time: the ramp is still under way at Run
        async with app.run_test(size=SIZE) as pilot:
            pilot = DriverPilot(app)
            await tui.ready(app, pilot)
            client = app.client
            await pilot.press("f8")
            tab, error = app.query_one(IdentifyTab), app.query_one("#identify-error")
            await tui.until(lambda: tab.visible_now, what="the Identify tab")
            handle = long_ramp(client)
            await tui.until(lambda: client.status().move_done > 100, what="the ramp under way")
            await pilot.press("ctrl+f")
            await tui.until(lambda: client.status().paused, what="the feed hold")
            await pilot.click("#identify-run")
            await tui.until(lambda: "feed hold" in str(error.render()),
                            what=lambda: f"the refusal: {error.render()!s}")
            assert tab.handle is None and not handle.done.is_set()
            assert client.status().move_id == handle.move_id and client.status().paused
            await pilot.press("ctrl+g")
            await asyncio.to_thread(client.wait, handle, 10)

    asyncio.run(scenario())


def test_feed_keys_step_from_the_override_in_force_not_from_their_own_count(tui) -> None:
    """A program's ``feed = 50`` step (the runner sets it on the TUI's own client, as here), or
    another client, sets the override: ^↓ 'feed −10 %' then took the TUI's own count (100 %)
    and set 90 %: the key for slower made the arm faster. Now it steps from the 50 % in force;
    a burst of keys still counts each (the status lags them)."""
    async def scenario() -> None:
        app = tui.app()
        async with app.run_test(size=SIZE) as pilot:
            pilot = DriverPilot(app)
            await tui.ready(app, pilot)
            client = app.client
            client.feed_override(0.5)  # the program's feed step
            await tui.until(lambda: client.status().feed_override == 0.5, what="50 %")
            await pilot.press("ctrl+down")
            await tui.until(lambda: client.status().feed_override != 0.5, what="a new override")
            assert client.status().feed_override == 0.4
            for _ in range(3):  # as fast as the terminal sends them
                tui.post_key(app, "ctrl+up")
            await tui.until(lambda: client.status().feed_override == 0.7,
                            what=lambda: f"70 %: {client.status().feed_override}")

    asyncio.run(scenario())


def test_with_the_controller_dead_the_global_keys_say_so_and_ask_nothing(tui, data_dir) -> None:
    """^R asked 'Release the E-stop?' and ^Y (in T1) 'Switch to automatic?' of a dead
    controller, to fail only after the yes; now each key says at once that the controller is
    not running and what to do, as the Jog tab's keys do."""
    async def scenario() -> None:
        app = PilotedApp("unimate2000b", "sim", None, data_dir, lockstep=True,
                         client_options={"heartbeat_timeout_s": 2.0}, build_behind=False)
        async with app.run_test(size=SIZE) as pilot:
            pilot = DriverPilot(app)
            await tui.ready(app, pilot)  # as the operator starts it: T1
            seen = tui.notifications(app)
            os.kill(app.client.pid, signal.SIGKILL)
            await tui.until(lambda: app.header.link.state == "dead", what="the death seen")
            for key in ("ctrl+r", "ctrl+y", "ctrl+g", "ctrl+f", "ctrl+down"):
                said = len(seen)
                await pilot.press(key)
                await tui.until(lambda n=said: any("the controller is not running — it died"
                                                   in m for m in seen[n:]),
                                what=lambda k=key, n=said: f"{k} to say why: {seen[n:]}")
                assert not isinstance(app.screen, ConfirmScreen), key

    asyncio.run(scenario())
