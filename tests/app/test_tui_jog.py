"""Jog tab: the keys change the duty the controller receives (option.c Manual()), the
hold-to-move mode stops a joint soon after its key is let go, the position jog moves
the hold target, and the rig's arrows step its duty by 10 %."""

from __future__ import annotations

import asyncio
import time

from app.tabs.jog import HOLD_DUTY_MAX, JogPad, KeyRepeat
from control.rt.commands import Manual
from control.rt.layout import Mode
from tests.app.test_tui_program import DriverPilot

SIZE = (160, 48)


def test_duty_keys_set_the_duty_the_controller_receives(tui) -> None:
    async def scenario() -> None:
        app = tui.app()
        async with app.run_test(size=SIZE) as pilot:
            pilot = DriverPilot(app)
            await tui.ready(app, pilot)
            client = app.client
            await pilot.press("5", "a", "a")
            await tui.until(lambda: client.status().duty[0] == 10.0, what="In/Out duty 10 %")
            status = client.status()
            assert status.mode == Mode.MANUAL_ACTUATE
            assert status.valve[0] == -10.0  # polarity -1: the valve sees the opposite sign
            await pilot.press("z", "3", "s", "n")
            await tui.until(lambda: client.status().duty[:2] == (5.0, 3.0)
                            and client.status().duty[5] == -3.0, what="duties 5, 3, -3")
            await pilot.press("space")
            await tui.until(lambda: not any(client.status().valve), what="all valves closed")
            await pilot.press("enter")
            await tui.until(lambda: client.status().mode == Mode.HOLD, what="back to hold")

    asyncio.run(scenario())


def test_leaving_the_jog_tab_stops_the_joints(tui) -> None:
    async def scenario() -> None:
        app = tui.app()
        async with app.run_test(size=SIZE) as pilot:
            pilot = DriverPilot(app)
            await tui.ready(app, pilot)
            client = app.client
            await pilot.press("9", "d")
            await tui.until(lambda: client.status().duty[2] == 9.0)
            await pilot.press("f4")
            await tui.until(lambda: client.status().mode == Mode.HOLD, what="hold after leaving")
            await pilot.press("a")  # the Status tab has no jog keys
            await asyncio.sleep(0.1)
            assert client.status().mode == Mode.HOLD

    asyncio.run(scenario())


def test_hold_to_move_stops_within_150_ms_of_release(tui) -> None:
    async def scenario() -> None:
        app = tui.app(lockstep=False)
        async with app.run_test(size=SIZE) as pilot:
            pilot = DriverPilot(app)
            await tui.ready(app, pilot)
            client = app.client
            await pilot.press("m", "2")  # hold-to-move at 20 %
            tui.post_key(app, "d")
            await tui.until(lambda: client.status().duty[2] == 20.0, timeout=2,
                            what="Up/Down moving while held")
            await asyncio.sleep(0.3)  # the terminal's initial repeat delay
            for _ in range(15):  # then auto-repeat every 30 ms
                tui.post_key(app, "d")
                await asyncio.sleep(0.03)
            assert client.status().duty[2] == 20.0, "still held while the key repeats"
            released = time.monotonic()
            await tui.until(lambda: client.status().mode == Mode.HOLD, timeout=1,
                            what="Up/Down holding after release")
            stopped = time.monotonic() - released
            # The design bound is the repeat timeout (≤ 110 ms, checked on the tab's own
            # tracker); the wall-clock figure includes this shared machine's scheduling, so
            # it is printed and held only to a bound no healthy run comes near.
            print(f"hold-to-move stopped {stopped * 1e3:.0f} ms after the last repeat")
            assert app.query_one(JogPad).repeat.repeat_timeout <= 0.15
            assert stopped < 0.5

    asyncio.run(scenario())


def test_hold_to_move_is_capped_and_holds_where_it_stopped(tui) -> None:
    """Increment 9 carried into hold-to-move gives the cap, 50 %, not 90 %; when the key is
    let go the controller holds the joint where it stopped (closed loop), rather than
    leaving it at zero duty in manual actuation, where Up/Down sags under its weight."""
    async def scenario() -> None:
        app = tui.app(lockstep=False)  # real time: Up/Down is far from its limit on release
        async with app.run_test(size=SIZE) as pilot:
            pilot = DriverPilot(app)
            await tui.ready(app, pilot)
            client = app.client
            await pilot.press("9", "m")
            assert "duty 50 % while held" in tui.text(app.query_one(JogPad))
            sent: list[object] = []
            send = client._send
            client._send = lambda command: (sent.append(command), send(command))[1]
            await pilot.press("c")  # Up/Down down, held for one press
            # what the press sent, not the brief manual mode (a loaded machine can miss it)
            await tui.until(lambda: any(isinstance(c, Manual) and c.duty[2] == -HOLD_DUTY_MAX
                                        for c in sent), what="Up/Down driven while held")
            client._send = send
            await tui.until(lambda: client.status().mode == Mode.HOLD, timeout=30,
                            what="hold after the release")
            status = client.status()
            assert abs(status.desired[2] - status.position[2]) < 0.5  # held where it stopped
            assert app.query_one(JogPad).duty == [0.0] * 6

    asyncio.run(scenario())


def test_position_jog_moves_the_hold_target(tui) -> None:
    async def scenario() -> None:
        app = tui.app()
        async with app.run_test(size=SIZE) as pilot:
            pilot = DriverPilot(app)
            before = await tui.ready(app, pilot)
            client = app.client
            await pilot.press("m", "m", "5")  # position mode, 1 mm or 0.2° a press
            await pilot.press("a", "a", "x")
            await tui.until(lambda: abs(client.status().desired[0] - before.desired[0] - 2.0)
                            < 1e-6 and abs(client.status().desired[1] - before.desired[1] + 0.2)
                            < 1e-6, what="In/Out target +2 mm, Rotate −0.2°")
            assert client.status().mode == Mode.HOLD
            assert "step 1 mm · 0.2° a press" in tui.text(app.query_one(JogPad))
            await pilot.press("9", "d", "d")  # the largest steps: 20 mm, 5°
            await tui.until(lambda: abs(client.status().desired[2] - before.desired[2] - 10.0)
                            < 1e-6, what="Up/Down target +10°")
            help_text = tui.text(app.query_one("#jog-help"))
            assert "0.05 0.1 0.2 0.5 1 2 5 10 20 mm" in help_text
            assert "0.01 0.02 0.05 0.1 0.2 0.5 1 2 5°" in help_text

    asyncio.run(scenario())


def test_position_jog_up_to_the_limit_with_keys_rests_inside_it_with_no_estop(tui) -> None:
    """Issue 25: Up/Down in 1° position-jog steps from 27° to 30° latched "feedback fault …
    frozen encoder" (the target on 30.00°, the arm on its stop at 29.99°). Now the target
    stops a goal tolerance inside the limit and the arm rests there, nothing latched."""
    async def scenario() -> None:
        app = tui.app()
        async with app.run_test(size=SIZE) as pilot:
            pilot = DriverPilot(app)
            await tui.ready(app, pilot)
            client = app.client
            updown = client.machine.joints[2]
            client.jog_position(2, 27.0 - client.status().desired[2])
            await tui.until(lambda: abs(client.status().position[2] - 27.0) < updown.tolerance,
                            timeout=30, what="Up/Down at 27°")
            await pilot.press("m", "m", "7")  # position mode, 1 mm or 1° a press
            for goal in (28.0, 29.0, updown.upper - updown.goal_tolerance):
                await pilot.press("d")
                await tui.until(lambda g=goal: abs(client.status().position[2] - g)
                                < updown.tolerance or client.status().estop, timeout=30,
                                what=f"Up/Down at {goal}°")
                assert not client.status().estop, client.status().fault
            await pilot.press("d")  # at the edge already: the target stays
            start = client.status().tick
            await tui.until(lambda: client.status().tick > start + 3_000, timeout=30,
                            what="three seconds of holding")
            status = client.status()
            assert not status.estop, status.fault
            assert status.desired[2] == updown.upper - updown.goal_tolerance
            assert abs(status.position[2] - status.desired[2]) < updown.goal_tolerance
            await pilot.pause()
            assert "E-STOP LATCHED" not in tui.text(app.screen)

    asyncio.run(scenario())


def test_rig_arrows_step_the_duty_by_ten_percent(tui) -> None:
    async def scenario() -> None:
        app = tui.app("rig")
        async with app.run_test(size=SIZE) as pilot:
            pilot = DriverPilot(app)
            await tui.ready(app, pilot)
            client = app.client
            await pilot.press("up", "up")
            await tui.until(lambda: client.status().duty == (20.0,), what="ram duty 20 %")
            await pilot.press("down")
            await tui.until(lambda: client.status().duty == (10.0,), what="ram duty 10 %")
            await pilot.press("space")
            await tui.until(lambda: client.status().valve == (0.0,), what="valve closed")

    asyncio.run(scenario())


def test_key_repeat_learns_the_terminal_and_sees_the_release() -> None:
    repeat = KeyRepeat()
    assert repeat.press(2, 0.0) is True
    assert repeat.released(0.4) == []  # waiting for the first repeat
    assert repeat.press(2, 0.45) is False  # the first repeat: initial delay learned
    assert repeat.first_timeout < 0.6
    t = 0.45
    for _ in range(20):
        t += 0.033
        assert repeat.press(2, t) is False
    assert repeat.repeat_timeout <= 0.11
    assert repeat.released(t + 0.05) == []
    assert repeat.released(t + repeat.repeat_timeout + 0.001) == [2]
    assert not repeat.held
    assert repeat.press(2, t + 1.0) is True  # a new press after the release


def test_the_jog_table_shows_each_joints_minimum_pwm_and_marks_a_duty_below_it(tui) -> None:
    """Section 5.4.1's minimum PWM per direction, in the controller output's sense
    (``output_min_pwm``: Rotate's valve sides need 22 and 18 %, polarity −1, so +18 / −22):
    a commanded +5 % is below its 18 % and marked, +23 % is not; −4 % is below the 22 % of
    that way, −22 % is not."""
    async def scenario() -> None:
        app = tui.app()
        async with app.run_test(size=SIZE) as pilot:
            pilot = DriverPilot(app)
            await tui.ready(app, pilot)
            table, note = app.query_one("#jog-table"), app.query_one("#jog-dead-band")
            assert "min PWM +/−" in tui.text(table)
            assert "18 / 22" in row(tui.text(table), "Rotate")
            assert "26 / 14" in row(tui.text(table), "Up/Down")
            await pilot.press("5", "s")
            await tui.until(lambda: "⚠" in row(tui.text(table), "Rotate"),
                            what="Rotate's +5 % marked")
            assert "Rotate +5 % (needs 18 %)" in tui.text(note)
            await pilot.press("9", "s", "s")  # +23 %: the valve opens
            await tui.until(lambda: "+23" in row(tui.text(table), "Rotate"))
            assert "⚠" not in row(tui.text(table), "Rotate")
            assert "will not move" not in tui.text(note)
            await pilot.press("x", "x", "x")  # −4 %: the other way needs 22 %
            await tui.until(lambda: "-4 ⚠" in row(tui.text(table), "Rotate"),
                            what="Rotate's −4 % marked")
            assert "Rotate -4 % (needs 22 %)" in tui.text(note)
            await pilot.press("x", "x")  # −22 %: as much as it needs
            await tui.until(lambda: "-22" in row(tui.text(table), "Rotate"))
            assert "⚠" not in row(tui.text(table), "Rotate")

    asyncio.run(scenario())


def row(text: str, joint: str) -> str:
    """The line of ``text`` that names ``joint``."""
    return next(line for line in text.splitlines() if f" {joint} " in line)
