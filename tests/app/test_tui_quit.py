"""Quitting (issue 13, item 8): ctrl+q asks first while a move runs or the E-stop is
latched, says why, and ``n`` leaves everything as it was; otherwise it quits at once."""

from __future__ import annotations

import asyncio

from app.tui import QuitScreen
from app.widgets.dialogs import ConfirmScreen
from control.motion import moves

SIZE = (160, 48)


def test_quitting_mid_move_asks_and_no_keeps_the_move_running(tui) -> None:
    async def scenario() -> None:
        app = tui.app(lockstep=False)  # a lockstep 20 s step ends in a second or two
        async with app.run_test(size=SIZE) as pilot:
            start = await tui.ready(app, pilot)
            client = app.client
            path = moves.step(start.position, "updown", start.position[2] + 2.0,
                              duration=20.0, machine=app.machine)
            handle = client.move(path, kind="step")
            await tui.until(lambda: client.status().moving, what="the move running")
            await pilot.press("ctrl+q")
            await tui.until(lambda: isinstance(app.screen, QuitScreen), what="the question")
            detail = tui.text(app.screen.query_one(".dialog-detail"))
            assert f"Move {handle.move_id} is running" in detail, detail
            await pilot.press("n")
            await tui.until(lambda: not isinstance(app.screen, QuitScreen), what="the answer")
            assert app.is_running and client.status().moving and not handle.done.is_set()
            await pilot.press("ctrl+q")
            await tui.until(lambda: isinstance(app.screen, QuitScreen), what="the question")
            await pilot.press("y")
            await tui.until(lambda: not app.is_running, what="the app to quit")

    asyncio.run(scenario())


def test_quitting_while_latched_asks_and_otherwise_quits_at_once(tui) -> None:
    async def scenario() -> None:
        app = tui.app()
        async with app.run_test(size=SIZE) as pilot:
            await tui.ready(app, pilot)
            await pilot.press("ctrl+e")
            await tui.until(lambda: app.client.status().estop, what="the latch")
            await pilot.press("ctrl+q")
            await tui.until(lambda: isinstance(app.screen, QuitScreen), what="the question")
            detail = tui.text(app.screen.query_one(".dialog-detail"))
            assert "E-stop is latched: operator E-stop" in detail, detail
            await pilot.press("n")
            await tui.until(lambda: not isinstance(app.screen, QuitScreen), what="the answer")
            assert app.is_running and app.client.status().estop
            # released (asked first), nothing runs and nothing is latched: ^Q quits unasked
            await pilot.press("ctrl+r")
            await tui.until(lambda: isinstance(app.screen, ConfirmScreen), what="the release")
            await pilot.press("y")
            await tui.until(lambda: not app.client.status().estop and not app.estop_latched,
                            what="the E-stop released")
            await pilot.press("ctrl+q")
            await tui.until(lambda: not app.is_running, what="the app to quit unasked")

    asyncio.run(scenario())
